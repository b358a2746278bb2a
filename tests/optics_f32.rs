//! The renderer's f32 film (4 wavelengths) against the f64 Airy film over a dense grid:
//! d 0–5000 nm, θ 0–89.9°, dielectric, absorbing and metal cases. Inputs are f32 values
//! (exactly what the renderer stores), promoted to f64 for the reference.

use num_complex::{Complex32, Complex64};
use thinfilm::optics::film_f32::ThinFilmX4;
use thinfilm::optics::ThinFilm;

#[test]
fn f32_film_within_1e5_of_f64() {
    let films: [(f32, (f32, f32), (f32, f32)); 7] = [
        (1.0, (1.37, 0.0), (1.64, 0.0)),
        (1.0, (2.37, 0.0), (1.64, 0.0)),
        (1.0, (1.33, 0.0), (1.0, 0.0)),
        (1.0, (1.5, 0.05), (0.18, 3.4)),
        (1.0, (2.2, 0.0), (1.38, 1.82)),
        (1.33, (1.0, 0.0), (1.5, 0.0)),
        (1.5, (1.2, 0.0), (1.0, 0.0)), // TIR in the film / substrate at steep angles
    ];
    let mut max_err = 0.0f64;
    let mut count = 0usize;
    for &(n1, n2, n3) in &films {
        for di in 0..=250 {
            let d = di as f32 * 20.0 + if di % 2 == 1 { 0.37 } else { 0.0 };
            let d = d.min(5000.0);
            for ai in 0..=60 {
                let deg = if ai == 60 { 89.9f32 } else { ai as f32 * 1.5 };
                let cos1 = deg.to_radians().cos();
                let x4 = ThinFilmX4 {
                    ambient_ior: n1,
                    film_ior: [Complex32::new(n2.0, n2.1); 4],
                    thickness_nm: d,
                    substrate_ior: [Complex32::new(n3.0, n3.1); 4],
                };
                let lambdas = [360.0f32 + ai as f32, 471.3, 598.7 + di as f32 * 0.1, 830.0];
                let got = x4.response(lambdas, cos1);
                let f = ThinFilm {
                    ambient_ior: n1 as f64,
                    film_ior: Complex64::new(n2.0 as f64, n2.1 as f64),
                    thickness_nm: d as f64,
                    substrate_ior: Complex64::new(n3.0 as f64, n3.1 as f64),
                };
                for (i, &l) in lambdas.iter().enumerate() {
                    let want = f.response(l as f64, cos1 as f64);
                    for (g, w) in [
                        (got.r_s[i], want.r_s),
                        (got.r_p[i], want.r_p),
                        (got.t_s[i], want.t_s),
                        (got.t_p[i], want.t_p),
                    ] {
                        let e = (g as f64 - w).abs();
                        assert!(
                            e < 1e-5,
                            "n1 {n1} n2 {n2:?} n3 {n3:?} d {d} θ {deg} λ {l}: f32 {g} f64 {w}"
                        );
                        max_err = max_err.max(e);
                    }
                    count += 1;
                }
            }
        }
    }
    println!("f32 vs f64 film: {count} evaluations, max |Δ| = {max_err:.3e}");
}
