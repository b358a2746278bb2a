//! XYZ ↔ linear sRGB (Rec.709, D65), the sRGB transfer curve, CIELAB (D65), ΔE*ab and ΔE00.
//!
//! The XYZ ↔ sRGB matrices are derived in full precision from the Rec.709 primaries
//! (x,y) = R (0.64, 0.33), G (0.30, 0.60), B (0.15, 0.06) and the white [`D65_WHITE_XYZ`],
//! so they are exact inverses and map that white to RGB (1,1,1). They agree with the 4-digit
//! IEC 61966-2-1 matrices to the printed digits and with Mitsuba 3's matrices within 3e-5.

/// Reference white of D65 with Y = 1 (matches the normalisation of the CIE tables).
pub const D65_WHITE_XYZ: [f64; 3] = [0.950_47, 1.0, 1.088_83];

/// XYZ → linear sRGB.
pub const XYZ_TO_SRGB: [[f64; 3]; 3] = [
    [
        3.240_454_162_114_105_4,
        -1.537_138_512_797_716_6,
        -0.498_531_409_556_016_16,
    ],
    [
        -0.969_266_030_505_187,
        1.876_010_845_446_694_4,
        0.041_556_017_530_349_85,
    ],
    [
        0.055_643_430_959_114_73,
        -0.204_025_913_516_753_84,
        1.057_225_188_223_179_1,
    ],
];

/// Linear sRGB → XYZ.
pub const SRGB_TO_XYZ: [[f64; 3]; 3] = [
    [
        0.412_456_439_089_692_15,
        0.357_576_077_643_908_9,
        0.180_437_483_266_398_9,
    ],
    [
        0.212_672_851_405_622_5,
        0.715_152_155_287_817_8,
        0.072_174_993_306_559_56,
    ],
    [
        0.019_333_895_582_329_3,
        0.119_192_025_881_302_94,
        0.950_304_078_536_367_7,
    ],
];

#[inline]
fn mat_vec(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// XYZ → linear sRGB (no chromatic adaptation, no clamping).
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f64; 3] {
    mat_vec(&XYZ_TO_SRGB, xyz)
}

/// Linear sRGB → XYZ.
pub fn linear_srgb_to_xyz(rgb: [f64; 3]) -> [f64; 3] {
    mat_vec(&SRGB_TO_XYZ, rgb)
}

/// sRGB transfer curve (linear → encoded), applied per channel (IEC 61966-2-1).
/// Negative values stay on the linear segment; NaN passes through.
pub fn srgb_encode(linear: f64) -> f64 {
    if linear <= 0.003_130_8 {
        12.92 * linear
    } else {
        1.055 * linear.powf(1.0 / 2.4) - 0.055
    }
}

/// Inverse sRGB transfer curve (encoded → linear).
pub fn srgb_decode(encoded: f64) -> f64 {
    if encoded <= 0.040_45 {
        encoded / 12.92
    } else {
        ((encoded + 0.055) / 1.055).powf(2.4)
    }
}

/// CIE 1976 lightness helper f(t) (CIE 15:2004 eq. 8.3–8.5, exact constants (6/29)³ and
/// 841/108 = 1/(3·(6/29)²)).
#[inline]
fn lab_f(t: f64) -> f64 {
    const DELTA: f64 = 6.0 / 29.0;
    if t > DELTA * DELTA * DELTA {
        t.cbrt()
    } else {
        t / (3.0 * DELTA * DELTA) + 4.0 / 29.0
    }
}

/// XYZ → CIELAB relative to `white` (use [`D65_WHITE_XYZ`] for D65).
pub fn xyz_to_lab(xyz: [f64; 3], white: [f64; 3]) -> [f64; 3] {
    let fx = lab_f(xyz[0] / white[0]);
    let fy = lab_f(xyz[1] / white[1]);
    let fz = lab_f(xyz[2] / white[2]);
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// CIELAB → XYZ relative to `white` (inverse of [`xyz_to_lab`]).
pub fn lab_to_xyz(lab: [f64; 3], white: [f64; 3]) -> [f64; 3] {
    const DELTA: f64 = 6.0 / 29.0;
    let finv = |f: f64| {
        if f > DELTA {
            f * f * f
        } else {
            3.0 * DELTA * DELTA * (f - 4.0 / 29.0)
        }
    };
    let fy = (lab[0] + 16.0) / 116.0;
    let fx = fy + lab[1] / 500.0;
    let fz = fy - lab[2] / 200.0;
    [
        white[0] * finv(fx),
        white[1] * finv(fy),
        white[2] * finv(fz),
    ]
}

/// CIE76 ΔE*ab.
pub fn delta_e76(lab1: [f64; 3], lab2: [f64; 3]) -> f64 {
    let d = [lab1[0] - lab2[0], lab1[1] - lab2[1], lab1[2] - lab2[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

/// CIEDE2000 ΔE00 (Sharma, Wu & Dalal 2005), kL = kC = kH = 1.
///
/// Follows the paper's equations (1)–(22), including its notes on the hue angle of neutral
/// colours (h' = 0 when a' = b = 0), on Δh' and the mean hue when C'₁C'₂ = 0, and on the
/// ±180° discontinuity of the mean hue. Hue differences within 1e-9° of 180° are treated as
/// exactly 180° (the "≤ 180°" branch): test pair 14 has h'₂ − h'₁ = 180° mathematically, and
/// atan2 rounding (≈3e-14°) must not flip it to the other side of the discontinuity, which
/// would give 4.7461 instead of the published 4.8045.
pub fn delta_e2000(lab1: [f64; 3], lab2: [f64; 3]) -> f64 {
    let [l1, a1, b1] = lab1;
    let [l2, a2, b2] = lab2;
    let pow7 = |x: f64| {
        let x2 = x * x;
        x2 * x2 * x2 * x
    };
    const POW25_7: f64 = 6_103_515_625.0; // 25⁷

    // (2)–(6): a' stretch by G based on the mean chroma.
    let c1 = a1.hypot(b1);
    let c2 = a2.hypot(b2);
    let c_mean = 0.5 * (c1 + c2);
    let c_mean7 = pow7(c_mean);
    let g = 0.5 * (1.0 - (c_mean7 / (c_mean7 + POW25_7)).sqrt());
    let a1p = (1.0 + g) * a1;
    let a2p = (1.0 + g) * a2;
    let c1p = a1p.hypot(b1);
    let c2p = a2p.hypot(b2);
    let hue = |b: f64, ap: f64| {
        if b == 0.0 && ap == 0.0 {
            0.0
        } else {
            let h = b.atan2(ap).to_degrees();
            if h < 0.0 {
                h + 360.0
            } else {
                h
            }
        }
    };
    let h1p = hue(b1, a1p);
    let h2p = hue(b2, a2p);

    // (8)–(11)
    let dlp = l2 - l1;
    let dcp = c2p - c1p;
    let cc = c1p * c2p;
    const HUE_EPS_DEG: f64 = 1e-9;
    let dhp = if cc == 0.0 {
        0.0
    } else {
        let d = h2p - h1p;
        if d > 180.0 + HUE_EPS_DEG {
            d - 360.0
        } else if d < -180.0 - HUE_EPS_DEG {
            d + 360.0
        } else {
            d
        }
    };
    let dhp_big = 2.0 * cc.sqrt() * (0.5 * dhp).to_radians().sin();

    // (12)–(22)
    let lp_mean = 0.5 * (l1 + l2);
    let cp_mean = 0.5 * (c1p + c2p);
    let hp_mean = if cc == 0.0 {
        h1p + h2p
    } else if (h1p - h2p).abs() <= 180.0 + HUE_EPS_DEG {
        0.5 * (h1p + h2p)
    } else if h1p + h2p < 360.0 {
        0.5 * (h1p + h2p + 360.0)
    } else {
        0.5 * (h1p + h2p - 360.0)
    };
    let t = 1.0 - 0.17 * (hp_mean - 30.0).to_radians().cos()
        + 0.24 * (2.0 * hp_mean).to_radians().cos()
        + 0.32 * (3.0 * hp_mean + 6.0).to_radians().cos()
        - 0.20 * (4.0 * hp_mean - 63.0).to_radians().cos();
    let d_theta = 30.0 * (-((hp_mean - 275.0) / 25.0).powi(2)).exp();
    let cp_mean7 = pow7(cp_mean);
    let r_c = 2.0 * (cp_mean7 / (cp_mean7 + POW25_7)).sqrt();
    let lm50 = (lp_mean - 50.0) * (lp_mean - 50.0);
    let s_l = 1.0 + 0.015 * lm50 / (20.0 + lm50).sqrt();
    let s_c = 1.0 + 0.045 * cp_mean;
    let s_h = 1.0 + 0.015 * cp_mean * t;
    let r_t = -(2.0 * d_theta).to_radians().sin() * r_c;

    let tl = dlp / s_l;
    let tc = dcp / s_c;
    let th = dhp_big / s_h;
    (tl * tl + tc * tc + th * th + r_t * tc * th).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrices_are_inverse_and_map_white_to_one() {
        let rgb = xyz_to_linear_srgb(D65_WHITE_XYZ);
        for c in rgb {
            assert!((c - 1.0).abs() < 1e-12, "{rgb:?}");
        }
        let back = linear_srgb_to_xyz(xyz_to_linear_srgb([0.3, 0.6, 0.2]));
        for (a, b) in back.iter().zip([0.3, 0.6, 0.2]) {
            assert!((a - b).abs() < 1e-12);
        }
        // IEC 61966-2-1 printed matrix (4 digits).
        let iec = [
            [3.2406, -1.5372, -0.4986],
            [-0.9689, 1.8758, 0.0415],
            [0.0557, -0.2040, 1.0570],
        ];
        for i in 0..3 {
            for j in 0..3 {
                assert!((XYZ_TO_SRGB[i][j] - iec[i][j]).abs() < 6e-4);
            }
        }
    }

    #[test]
    fn srgb_curve_round_trip_and_knee() {
        for i in 0..=100 {
            let x = i as f64 / 100.0;
            assert!((srgb_decode(srgb_encode(x)) - x).abs() < 1e-12);
        }
        // Continuous at the knee.
        let k = 0.003_130_8;
        assert!((12.92 * k - (1.055 * f64::powf(k, 1.0 / 2.4) - 0.055)).abs() < 1e-6);
        assert!((srgb_encode(1.0) - 1.0).abs() < 1e-15);
        assert!(srgb_encode(f64::NAN).is_nan());
        assert!((srgb_encode(0.18) - 0.461_356).abs() < 1e-5);
    }

    #[test]
    fn lab_white_black_round_trip() {
        let w = xyz_to_lab(D65_WHITE_XYZ, D65_WHITE_XYZ);
        assert!((w[0] - 100.0).abs() < 1e-12 && w[1].abs() < 1e-12 && w[2].abs() < 1e-12);
        let k = xyz_to_lab([0.0; 3], D65_WHITE_XYZ);
        assert!(k[0].abs() < 1e-12);
        for xyz in [[0.2, 0.3, 0.4], [0.001, 0.002, 0.0005], [0.9, 0.8, 1.2]] {
            let back = lab_to_xyz(xyz_to_lab(xyz, D65_WHITE_XYZ), D65_WHITE_XYZ);
            for (a, b) in back.iter().zip(xyz) {
                assert!((a - b).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn delta_e_basics() {
        let a = [50.0, 2.6772, -79.7751];
        let b = [50.0, 0.0, -82.7485];
        assert!((delta_e2000(a, b) - 2.0425).abs() < 1e-4);
        assert_eq!(delta_e2000(a, a), 0.0);
        assert!((delta_e76([0.0; 3], [3.0, 4.0, 0.0]) - 5.0).abs() < 1e-12);
        // Symmetric.
        assert!((delta_e2000(a, b) - delta_e2000(b, a)).abs() < 1e-12);
        assert!(delta_e2000([f64::NAN, 0.0, 0.0], a).is_nan());
        // Sharma pair 14 (hue difference exactly 180°).
        let d14 = delta_e2000([50.0, -0.001, 2.49], [50.0, 0.001, -2.49]);
        assert!((d14 - 4.8045).abs() < 1e-4, "{d14}");
        // Both neutral: pure lightness difference.
        let dl = delta_e2000([50.0, 0.0, 0.0], [60.0, 0.0, 0.0]);
        assert!(dl > 0.0 && dl < 10.0);
    }
}
