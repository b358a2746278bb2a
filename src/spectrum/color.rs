//! XYZ ↔ linear sRGB (Rec.709, D65), the sRGB transfer curve, CIELAB (D65), ΔE*ab and ΔE00.

/// Reference white of D65 with Y = 1 (matches the normalisation of the CIE tables).
pub const D65_WHITE_XYZ: [f64; 3] = [0.950_47, 1.0, 1.088_83];

/// XYZ → linear sRGB (IEC 61966-2-1 matrix, no chromatic adaptation).
pub fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f64; 3] {
    let _ = xyz;
    todo!("foundation")
}

/// Linear sRGB → XYZ.
pub fn linear_srgb_to_xyz(rgb: [f64; 3]) -> [f64; 3] {
    let _ = rgb;
    todo!("foundation")
}

/// sRGB transfer curve (linear → encoded), applied per channel.
pub fn srgb_encode(linear: f64) -> f64 {
    let _ = linear;
    todo!("foundation")
}

/// Inverse sRGB transfer curve (encoded → linear).
pub fn srgb_decode(encoded: f64) -> f64 {
    let _ = encoded;
    todo!("foundation")
}

/// XYZ → CIELAB relative to `white` (use [`D65_WHITE_XYZ`] for D65).
pub fn xyz_to_lab(xyz: [f64; 3], white: [f64; 3]) -> [f64; 3] {
    let _ = (xyz, white);
    todo!("foundation")
}

/// CIE76 ΔE*ab.
pub fn delta_e76(lab1: [f64; 3], lab2: [f64; 3]) -> f64 {
    let _ = (lab1, lab2);
    todo!("foundation")
}

/// CIEDE2000 ΔE00 (Sharma, Wu & Dalal 2005), kL = kC = kH = 1.
pub fn delta_e2000(lab1: [f64; 3], lab2: [f64; 3]) -> f64 {
    let _ = (lab1, lab2);
    todo!("foundation")
}
