//! `thinfilm bench optics`: single-film evaluations per second (R_s, R_p, T_s, T_p at 4
//! wavelengths = one hero bundle), f64 Airy, f64 transfer matrix and the renderer's f32 path.
//! Single thread; build with `--release` for meaningful numbers.

use num_complex::{Complex32, Complex64};
use std::hint::black_box;
use std::time::{Duration, Instant};
use thinfilm::optics::film_f32::ThinFilmX4;
use thinfilm::optics::{Stack, ThinFilm};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Seconds to run each variant.
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
}

/// Runs `step(i)` in batches until `seconds` elapse; returns evaluations per second.
fn measure(seconds: f64, mut step: impl FnMut(u32) -> f32) -> f64 {
    let budget = Duration::from_secs_f64(seconds.max(0.01));
    let start = Instant::now();
    let mut n = 0u64;
    let mut sink = 0.0f32;
    while start.elapsed() < budget {
        for i in 0..4096u32 {
            sink += step(i);
        }
        n += 4096;
    }
    black_box(sink);
    n as f64 / start.elapsed().as_secs_f64()
}

pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        anyhow::bail!("--seconds must be > 0, got {}", args.seconds);
    }
    let lambdas = [450.0, 520.0, 610.0, 700.0];
    let film = ThinFilm {
        ambient_ior: 1.0,
        film_ior: Complex64::new(1.37, 0.0),
        thickness_nm: 400.0,
        substrate_ior: Complex64::new(1.64, 0.0),
    };
    let cos_of = |i: u32| 0.2 + 0.8 * ((i & 1023) as f64 / 1023.0);
    // Thickness varies with i so nothing is hoisted out of the loop.
    let d_of = |i: u32| 50.0 + (i & 4095) as f64;

    let f64_airy = measure(args.seconds, |i| {
        let f = ThinFilm {
            thickness_nm: d_of(i),
            ..black_box(film)
        };
        let c = cos_of(i);
        let mut s = 0.0;
        for &l in &lambdas {
            let r = f.response(l, c);
            s += r.r_s + r.r_p + r.t_s + r.t_p;
        }
        s as f32
    });
    let f64_tmm = measure(args.seconds, |i| {
        let f = ThinFilm {
            thickness_nm: d_of(i),
            ..black_box(film)
        };
        let st = Stack::from(&f);
        let c = cos_of(i);
        let mut s = 0.0;
        for &l in &lambdas {
            let r = st.response(l, c);
            s += r.r_s + r.r_p + r.t_s + r.t_p;
        }
        s as f32
    });
    let x4 = ThinFilmX4 {
        ambient_ior: 1.0,
        film_ior: [Complex32::new(1.37, 0.0); 4],
        thickness_nm: 400.0,
        substrate_ior: [Complex32::new(1.64, 0.0); 4],
    };
    let l32 = lambdas.map(|l| l as f32);
    let f32_x4 = measure(args.seconds, |i| {
        let f = ThinFilmX4 {
            thickness_nm: d_of(i) as f32,
            ..black_box(x4)
        };
        let r = f.response(l32, cos_of(i) as f32);
        (0..4)
            .map(|k| r.r_s[k] + r.r_p[k] + r.t_s[k] + r.t_p[k])
            .sum()
    });
    println!("single-film evaluations per second (4 wavelengths, R_s R_p T_s T_p; 1 thread):");
    println!(
        "  f64 Airy (ThinFilm::response ×4)  {:>8.2} M/s",
        f64_airy / 1e6
    );
    println!(
        "  f64 TMM  (Stack::response ×4)     {:>8.2} M/s",
        f64_tmm / 1e6
    );
    println!(
        "  f32 Airy (ThinFilmX4::response)   {:>8.2} M/s",
        f32_x4 / 1e6
    );
    if cfg!(debug_assertions) {
        println!("  (debug build: numbers are not representative; use --release)");
    }
    Ok(())
}
