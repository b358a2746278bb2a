//! Writes the Jakob & Hanika (2019) sRGB coefficient table used by thinfilm's RGB → spectrum
//! upsampling, `spectra/srgb_rgb2spec_64.coeff`, in the "SPEC" format of
//! mitsuba-renderer/rgb2spec (magic, u32 res, res f32 z-nodes, `[3][res][res][res][3]` f32
//! coefficients for λ in nm) at Mitsuba 3's resolution, 64.
//!
//! Usage (from the repository root):
//!   cargo run --release --manifest-path tools/rgb2spec/Cargo.toml -- spectra/srgb_rgb2spec_64.coeff
//!
//! The algorithm is `rgb2spec_opt` (Jakob & Hanika 2019; pbrt-v4 and Mitsuba 3 run it at build
//! time): for every table node the sigmoid polynomial S(c0 t² + c1 t + c2), t = (λ−360)/470,
//! is fitted so that its colour under D65 matches the node's sRGB colour in CIELAB; nodes are
//! visited along z from res/5 upwards and then downwards, each warm-started from its
//! neighbour; coefficients are capped at 200 (pbrt-v4) to keep the sigmoid smooth. Two
//! differences, both to make thinfilm's round trip exact rather than approximate:
//! * the quadrature is thinfilm's own: CIE 1931 2° and D65 at 1 nm over 360–830 nm, read
//!   from `spectra/*.csv`, and the XYZ ↔ sRGB matrix of `src/spectrum/color.rs`;
//! * the solver is Levenberg–Marquardt with the analytic Jacobian (as current Mitsuba
//!   rgb2spec), in f64, up to 200 iterations, instead of pbrt-v4's 15 Gauss–Newton steps.
//!   The `rgb2spec` crate (a port of the pbrt-v4 version) left 8,132 of 786,432 nodes with
//!   round-trip errors above 2e-3 (up to 0.038), mostly dark colours; this solver leaves 7
//!   (worst 2.5e-3; Mitsuba's own table: 0, worst 1.1e-3).
//!
//! The output is written to `<out>.tmp` and renamed; the optimisation time and the worst
//! node residuals are printed.

// 3×3 matrix code reads best with explicit indices.
#![allow(clippy::needless_range_loop)]

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

const RES: usize = 64;
const LAMBDA_MIN: f64 = 360.0;
const LAMBDA_RANGE: f64 = 470.0;
const MAX_COEFF: f64 = 200.0;

/// Same matrix as src/spectrum/color.rs (Rec.709 primaries, white (0.95047, 1, 1.08883)).
const SRGB_TO_XYZ: [[f64; 3]; 3] = [
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

/// Quadrature: normalised wavelength t_i and XYZ weights D65·cmf/Σ(D65·ȳ) at 1 nm.
struct Quadrature {
    t: Vec<f64>,
    w: Vec<[f64; 3]>,
    white: [f64; 3],
}

fn read_table(path: &Path, ncols: usize) -> Result<Vec<Vec<f64>>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut rows = Vec::new();
    let mut header = true;
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() || line.starts_with('#') {
            continue;
        }
        if header {
            header = false;
            continue;
        }
        let v: Result<Vec<f64>, _> = line.split(',').map(|s| s.trim().parse::<f64>()).collect();
        match v {
            Ok(v) if v.len() == ncols => rows.push(v),
            _ => return Err(format!("{}:{}: malformed row", path.display(), n + 1)),
        }
    }
    Ok(rows)
}

fn quadrature(root: &Path) -> Result<Quadrature, String> {
    let cmf = read_table(&root.join("spectra/cie1931_2deg_cmf_1nm.csv"), 4)?;
    let d65 = read_table(&root.join("spectra/cie_d65_1nm.csv"), 2)?;
    if cmf.len() != 471 || d65.len() != 471 {
        return Err("tables must have 471 rows (360..=830 nm)".into());
    }
    let norm: f64 = cmf.iter().zip(&d65).map(|(c, d)| c[2] * d[1]).sum();
    let mut q = Quadrature {
        t: Vec::new(),
        w: Vec::new(),
        white: [0.0; 3],
    };
    for (c, d) in cmf.iter().zip(&d65) {
        if c[0] != d[0] {
            return Err("CMF and D65 wavelengths differ".into());
        }
        let w = [c[1] * d[1] / norm, c[2] * d[1] / norm, c[3] * d[1] / norm];
        q.t.push((c[0] - LAMBDA_MIN) / LAMBDA_RANGE);
        for k in 0..3 {
            q.white[k] += w[k];
        }
        q.w.push(w);
    }
    Ok(q)
}

/// CIELAB f(t) and its derivative.
fn lab_f(t: f64) -> (f64, f64) {
    const D: f64 = 6.0 / 29.0;
    if t > D * D * D {
        let c = t.cbrt();
        (c, 1.0 / (3.0 * c * c))
    } else {
        (t / (3.0 * D * D) + 4.0 / 29.0, 1.0 / (3.0 * D * D))
    }
}

/// Lab of `xyz` and ∂Lab/∂XYZ.
fn lab(xyz: [f64; 3], white: [f64; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let (fx, dx) = lab_f(xyz[0] / white[0]);
    let (fy, dy) = lab_f(xyz[1] / white[1]);
    let (fz, dz) = lab_f(xyz[2] / white[2]);
    let (dx, dy, dz) = (dx / white[0], dy / white[1], dz / white[2]);
    (
        [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)],
        [
            [0.0, 116.0 * dy, 0.0],
            [500.0 * dx, -500.0 * dy, 0.0],
            [0.0, 200.0 * dy, -200.0 * dz],
        ],
    )
}

/// Residual Lab(spectrum) − Lab(target) and its Jacobian w.r.t. the normalised coefficients.
fn residual(q: &Quadrature, c: [f64; 3], target_lab: [f64; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut xyz = [0.0; 3];
    let mut dxyz = [[0.0; 3]; 3]; // [xyz][coeff]
    for (t, w) in q.t.iter().zip(&q.w) {
        let x = (c[0] * t + c[1]) * t + c[2];
        let s2 = 1.0 + x * x;
        let s = 0.5 + x / (2.0 * s2.sqrt());
        let ds = 0.5 / (s2 * s2.sqrt());
        let g = [t * t * ds, t * ds, ds];
        for a in 0..3 {
            xyz[a] += s * w[a];
            for b in 0..3 {
                dxyz[a][b] += g[b] * w[a];
            }
        }
    }
    let (l, dl) = lab(xyz, q.white);
    let mut j = [[0.0; 3]; 3];
    for a in 0..3 {
        for b in 0..3 {
            j[a][b] = (0..3).map(|m| dl[a][m] * dxyz[m][b]).sum();
        }
    }
    (
        [
            l[0] - target_lab[0],
            l[1] - target_lab[1],
            l[2] - target_lab[2],
        ],
        j,
    )
}

fn norm2(r: [f64; 3]) -> f64 {
    r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
}

/// Solve a 3×3 system by Cramer's rule; None if singular.
fn solve3(m: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(m);
    if !d.is_finite() || d.abs() < 1e-300 {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut mk = m;
        for r in 0..3 {
            mk[r][k] = b[r];
        }
        *xk = det(mk) / d;
    }
    Some(x)
}

fn cap(mut c: [f64; 3]) -> [f64; 3] {
    let m = c.iter().fold(0.0f64, |a, v| a.max(v.abs()));
    if m > MAX_COEFF {
        for v in &mut c {
            *v *= MAX_COEFF / m;
        }
    }
    c
}

/// Levenberg–Marquardt fit from `c0`. Returns coefficients and the final |ΔLab|.
fn fit(q: &Quadrature, rgb: [f64; 3], c0: [f64; 3]) -> ([f64; 3], f64) {
    let xyz: [f64; 3] = std::array::from_fn(|a| (0..3).map(|b| SRGB_TO_XYZ[a][b] * rgb[b]).sum());
    let (target, _) = lab(xyz, q.white);
    let mut c = cap(c0);
    let (mut r, mut j) = residual(q, c, target);
    let mut err = norm2(r);
    let mut mu = 1e-3;
    for _ in 0..200 {
        if err < 1e-14 {
            break;
        }
        // Normal equations JᵀJ δ = −Jᵀr with Marquardt's diagonal damping.
        let mut a = [[0.0; 3]; 3];
        let mut g = [0.0; 3];
        for p in 0..3 {
            for s in 0..3 {
                a[p][s] = (0..3).map(|m| j[m][p] * j[m][s]).sum();
            }
            g[p] = -(0..3).map(|m| j[m][p] * r[m]).sum::<f64>();
        }
        let mut improved = false;
        for _ in 0..30 {
            let mut ad = a;
            for p in 0..3 {
                ad[p][p] += mu * a[p][p].max(1e-12);
            }
            let Some(d) = solve3(ad, g) else {
                mu *= 10.0;
                continue;
            };
            let cn = cap([c[0] + d[0], c[1] + d[1], c[2] + d[2]]);
            let (rn, jn) = residual(q, cn, target);
            let en = norm2(rn);
            if en.is_finite() && en < err {
                let rel = (err - en) / err.max(1e-300);
                c = cn;
                r = rn;
                j = jn;
                err = en;
                mu = (mu / 3.0).max(1e-12);
                improved = rel > 1e-12;
                break;
            }
            mu *= 4.0;
        }
        if !improved {
            break;
        }
    }
    (c, err.sqrt())
}

fn smoothstep(x: f64) -> f64 {
    x * x * (3.0 - 2.0 * x)
}

fn main() -> ExitCode {
    let out = match std::env::args_os().nth(1) {
        Some(p) => PathBuf::from(p),
        None => {
            eprintln!("usage: thinfilm-rgb2spec-gen OUTPUT.coeff   (run from the repository root)");
            return ExitCode::from(2);
        }
    };
    let q = match quadrature(Path::new(".")) {
        Ok(q) => q,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let t0 = Instant::now();
    let scale: Vec<f64> = (0..RES)
        .map(|k| smoothstep(smoothstep(k as f64 / (RES - 1) as f64)))
        .collect();
    // Stored as f32; fit against the f32 node values the lookup will use.
    let scale: Vec<f64> = scale.iter().map(|&v| v as f32 as f64).collect();
    let mut data = vec![0.0f32; 3 * RES * RES * RES * 3];
    let worst = Mutex::new((0.0f64, [0.0f64; 3]));
    let next = AtomicUsize::new(0);
    let data_lock = Mutex::new(&mut data);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let job = next.fetch_add(1, Ordering::Relaxed);
                if job >= 3 * RES {
                    break;
                }
                let (l, j) = (job / RES, job % RES);
                let y = j as f64 / (RES - 1) as f64;
                let mut local = Vec::with_capacity(RES * RES);
                let mut local_worst = (0.0f64, [0.0f64; 3]);
                for i in 0..RES {
                    let x = i as f64 / (RES - 1) as f64;
                    let start = RES / 5;
                    let mut run = |ks: &mut dyn Iterator<Item = usize>| {
                        let mut c = [0.0; 3];
                        for k in ks {
                            let b = scale[k];
                            let mut rgb = [0.0; 3];
                            rgb[l] = b;
                            rgb[(l + 1) % 3] = x * b;
                            rgb[(l + 2) % 3] = y * b;
                            let (cn, e) = fit(&q, rgb, c);
                            c = cn;
                            if e > local_worst.0 && b > 0.0 {
                                local_worst = (e, rgb);
                            }
                            // Normalised t → λ in nm (rgb2spec_opt's remapping).
                            let (c0, c1) = (LAMBDA_MIN, 1.0 / LAMBDA_RANGE);
                            let (a, bb, cc) = (c[0], c[1], c[2]);
                            local.push((
                                k,
                                i,
                                [
                                    (a * c1 * c1) as f32,
                                    (bb * c1 - 2.0 * a * c0 * c1 * c1) as f32,
                                    (cc - bb * c0 * c1 + a * (c0 * c1) * (c0 * c1)) as f32,
                                ],
                            ));
                        }
                    };
                    run(&mut (start..RES));
                    run(&mut (0..start).rev());
                }
                let mut d = data_lock.lock().unwrap();
                for (k, i, c) in local {
                    let idx = (((l * RES + k) * RES + j) * RES + i) * 3;
                    d[idx..idx + 3].copy_from_slice(&c);
                }
                drop(d);
                let mut w = worst.lock().unwrap();
                if local_worst.0 > w.0 {
                    *w = local_worst;
                }
            });
        }
    });
    let secs = t0.elapsed().as_secs_f64();
    let (worst_lab, worst_rgb) = *worst.lock().unwrap();

    let mut bytes = Vec::with_capacity(8 + 4 * (RES + data.len()));
    bytes.extend_from_slice(b"SPEC");
    bytes.extend_from_slice(&(RES as u32).to_le_bytes());
    for v in &scale {
        bytes.extend_from_slice(&(*v as f32).to_le_bytes());
    }
    for v in &data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let mut tmp = out.clone().into_os_string();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    if let Err(e) = std::fs::write(&tmp, &bytes).and_then(|_| std::fs::rename(&tmp, &out)) {
        eprintln!("error: cannot write {}: {e}", out.display());
        let _ = std::fs::remove_file(&tmp);
        return ExitCode::FAILURE;
    }
    println!(
        "wrote {} (sRGB, res {RES}, {} bytes) — optimisation took {secs:.1} s on {threads} thread(s); \
         worst node |ΔLab| = {worst_lab:.3e} at rgb {worst_rgb:?}",
        out.display(),
        bytes.len()
    );
    ExitCode::SUCCESS
}
