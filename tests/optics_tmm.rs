//! Our Airy film and transfer-matrix stacks against the `tmm` package (coh_tmm, inc_tmm).
//! Reference: tests/data/tmm/reference.csv, written by `python3 tools/tmm_reference.py`.

use num_complex::Complex64;
use thinfilm::optics::{Coherence, Layer, Stack, ThinFilm};

struct Case {
    line: usize,
    kind: String,
    stack: Stack,
    lambda_nm: f64,
    angle_deg: f64,
    want: [f64; 4], // R_s, T_s, R_p, T_p
}

fn cases() -> Vec<Case> {
    let text = include_str!("data/tmm/reference.csv");
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.starts_with("kind,") {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 11, "line {}", i + 1);
        let num = |s: &str| {
            s.parse::<f64>()
                .unwrap_or_else(|e| panic!("line {}: {s}: {e}", i + 1))
        };
        let layers = f[6]
            .split(';')
            .filter(|s| !s.is_empty())
            .map(|l| {
                let p: Vec<&str> = l.split(':').collect();
                Layer {
                    ior: Complex64::new(num(p[0]), num(p[1])),
                    thickness_nm: num(p[2]),
                    coherence: if p[3] == "i" {
                        Coherence::Incoherent
                    } else {
                        Coherence::Coherent
                    },
                }
            })
            .collect();
        out.push(Case {
            line: i + 1,
            kind: f[0].to_string(),
            stack: Stack {
                ambient_ior: num(f[3]),
                layers,
                substrate_ior: Complex64::new(num(f[4]), num(f[5])),
            },
            lambda_nm: num(f[1]),
            angle_deg: num(f[2]),
            want: [num(f[7]), num(f[8]), num(f[9]), num(f[10])],
        });
    }
    out
}

#[test]
fn matches_tmm_reference() {
    let cases = cases();
    assert!(cases.len() >= 500, "only {} cases", cases.len());
    let (mut max_dr, mut max_dt) = (0.0f64, 0.0f64);
    let (mut n_film, mut n_stack, mut n_inc) = (0, 0, 0);
    for c in &cases {
        let got = c.stack.response_at_angle(c.lambda_nm, c.angle_deg).unwrap();
        let got = [got.r_s, got.t_s, got.r_p, got.t_p];
        let dr = (got[0] - c.want[0]).abs().max((got[2] - c.want[2]).abs());
        let dt = (got[1] - c.want[1]).abs().max((got[3] - c.want[3]).abs());
        assert!(
            dr < 1e-10 && dt < 1e-10,
            "line {} ({}): got {got:?}, tmm {:?}",
            c.line,
            c.kind,
            c.want
        );
        max_dr = max_dr.max(dr);
        max_dt = max_dt.max(dt);
        // Single coherent films also go through the Airy code path.
        if c.kind == "coh" && c.stack.layers.len() == 1 {
            n_film += 1;
            let f = ThinFilm {
                ambient_ior: c.stack.ambient_ior,
                film_ior: c.stack.layers[0].ior,
                thickness_nm: c.stack.layers[0].thickness_nm,
                substrate_ior: c.stack.substrate_ior,
            };
            let a = f.response_at_angle(c.lambda_nm, c.angle_deg).unwrap();
            let a = [a.r_s, a.t_s, a.r_p, a.t_p];
            for k in 0..4 {
                let d = (a[k] - c.want[k]).abs();
                assert!(d < 1e-10, "Airy line {}: {a:?} vs {:?}", c.line, c.want);
                if k % 2 == 0 {
                    max_dr = max_dr.max(d);
                } else {
                    max_dt = max_dt.max(d);
                }
            }
        } else if c.kind == "coh" {
            n_stack += 1;
        } else {
            n_inc += 1;
        }
    }
    assert!(n_film >= 300 && n_stack >= 200 && n_inc >= 100);
    println!(
        "tmm reference: {} cases ({n_film} films, {n_stack} stacks, {n_inc} incoherent): \
         max |ΔR| = {max_dr:.3e}, max |ΔT| = {max_dt:.3e}",
        cases.len()
    );
}
