//! Criterion micro-benchmark: one thin-film evaluation at 4 wavelengths, f64 and f32.
//! `cargo bench --bench optics`

use criterion::{criterion_group, criterion_main, Criterion};
use num_complex::{Complex32, Complex64};
use std::hint::black_box;
use thinfilm::optics::film_f32::ThinFilmX4;
use thinfilm::optics::{Stack, ThinFilm};

fn bench(c: &mut Criterion) {
    let film = ThinFilm {
        ambient_ior: 1.0,
        film_ior: Complex64::new(1.37, 0.0),
        thickness_nm: 400.0,
        substrate_ior: Complex64::new(1.64, 0.0),
    };
    let lambdas = [450.0, 520.0, 610.0, 700.0];
    c.bench_function("film_f64_x4", |b| {
        b.iter(|| {
            let f = black_box(film);
            lambdas.map(|l| f.response(l, black_box(0.8)))
        })
    });
    let stack = Stack::from(&film);
    c.bench_function("stack_tmm_f64_x4", |b| {
        b.iter(|| {
            let s = black_box(&stack);
            lambdas.map(|l| s.response(l, black_box(0.8)))
        })
    });
    let x4 = ThinFilmX4 {
        ambient_ior: 1.0,
        film_ior: [Complex32::new(1.37, 0.0); 4],
        thickness_nm: 400.0,
        substrate_ior: [Complex32::new(1.64, 0.0); 4],
    };
    let l32 = lambdas.map(|l| l as f32);
    c.bench_function("film_f32_x4", |b| {
        b.iter(|| black_box(x4).response(black_box(l32), black_box(0.8)))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
