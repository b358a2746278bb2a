//! Area lights against closed-form irradiance.
//!
//! A grey diffuse floor (reflectance ρ) lit by one emitter of radiance Le reflects
//! L = ρ · Le · F, where F = E / (π Le) is the point-to-emitter form factor, known in closed
//! form for a rectangle parallel to the floor and for a sphere above the horizon. A
//! narrow-field camera looks at one floor point from the side, so every pixel sees (nearly)
//! the same point; its mean must match the closed form within 2 %, at points straight under
//! the light and beside it, at heights 0.5–3.
//!
//! These would have caught the self-occluding shadow rays (the light sample's ray was moved
//! off the floor but kept its length, so it ended inside the emitter: only points straight
//! under a light were lit) and the reflective default BSDF of emitters (Mitsuba gives an
//! emitter without a BSDF a black one).

use std::f64::consts::PI;
use std::path::Path;
use thinfilm::render::{render, RenderOptions};
use thinfilm::scene::mitsuba::load_str;

const RHO: f64 = 0.5;
const LE: f64 = 10.0;

/// Form factor from a point to the rectangle [0, x] × [0, z] of a parallel plane at height h
/// over one of its corners (Howell's catalogue, configuration B-3), signed by the quadrant.
fn corner_form_factor(x: f64, z: f64, h: f64) -> f64 {
    let (a, b) = (x.abs() / h, z.abs() / h);
    let (sa, sb) = ((1.0 + a * a).sqrt(), (1.0 + b * b).sqrt());
    let f = (a / sa * (b / sa).atan() + b / sb * (a / sb).atan()) / (2.0 * PI);
    f * x.signum() * z.signum()
}

/// Form factor from the floor point (px, pz) to the rectangle [x0, x1] × [z0, z1] at height h.
fn rectangle_form_factor(px: f64, pz: f64, x: [f64; 2], z: [f64; 2], h: f64) -> f64 {
    let f = |xx: f64, zz: f64| corner_form_factor(xx - px, zz - pz, h);
    f(x[1], z[1]) - f(x[0], z[1]) - f(x[1], z[0]) + f(x[0], z[0])
}

/// Mean of a render of the floor point `target` seen from the side through a 0.5° field.
fn render_floor_point(emitter_xml: &str, target: [f64; 2], spp: u32, dir: &Path) -> [f64; 3] {
    let [tx, tz] = target;
    let xml = format!(
        r#"<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="8"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="0.5"/>
    <transform name="to_world">
      <lookat origin="{ox}, 0.35, {tz}" target="{tx}, 0, {tz}" up="0, 1, 0"/>
    </transform>
    <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    <film type="hdrfilm">
      <integer name="width" value="8"/><integer name="height" value="8"/>
      <rfilter type="box"/>
    </film>
  </sensor>
  <shape type="rectangle">
    <transform name="to_world"><scale value="20"/><rotate x="1" angle="-90"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="{RHO}, {RHO}, {RHO}"/></bsdf>
  </shape>
  {emitter_xml}
</scene>"#,
        ox = tx + 1.5,
    );
    let scene = load_str(&xml, dir, &[], "area_light_test.xml").expect("scene parses");
    let out = render(
        &scene,
        &RenderOptions {
            seed: Some(3),
            ..Default::default()
        },
    )
    .expect("render");
    let px = &out.image.pixels;
    let n = px.len() as f64;
    let mut mean = [0.0; 3];
    for p in px {
        for c in 0..3 {
            mean[c] += p[c] as f64 / n;
        }
    }
    mean
}

fn assert_close(what: &str, got: [f64; 3], want: f64, tol: f64) {
    for (c, g) in got.iter().enumerate() {
        let rel = g / want - 1.0;
        assert!(
            rel.abs() <= tol,
            "{what}: channel {c} = {g:.5}, closed form {want:.5} ({:+.2} %)",
            100.0 * rel
        );
    }
}

fn rectangle_emitter(half: f64, h: f64) -> String {
    format!(
        r#"<shape type="rectangle">
    <transform name="to_world">
      <scale value="{half}"/><rotate x="1" angle="90"/><translate y="{h}"/>
    </transform>
    <emitter type="area"><rgb name="radiance" value="{LE}, {LE}, {LE}"/></emitter>
  </shape>"#
    )
}

#[test]
fn rectangle_light_over_a_floor_matches_the_form_factor() {
    let dir = tempfile::tempdir().unwrap();
    let half = 0.2;
    for h in [0.5, 1.0, 1.5, 2.0, 3.0] {
        for target in [[0.0, 0.0], [0.6, 0.0], [0.3, -0.9]] {
            let f = rectangle_form_factor(target[0], target[1], [-half, half], [-half, half], h);
            let want = RHO * LE * f;
            let got = render_floor_point(&rectangle_emitter(half, h), target, 256, dir.path());
            assert_close(
                &format!("rectangle at h = {h}, floor point {target:?}"),
                got,
                want,
                0.02,
            );
        }
    }
}

#[test]
fn obj_quad_emitter_matches_the_form_factor() {
    let dir = tempfile::tempdir().unwrap();
    // A 0.4 × 0.6 quad at height 1.2 facing down, as two triangles in an OBJ file.
    let (x, z, h) = ([-0.1, 0.3], [-0.4, 0.2], 1.2);
    std::fs::write(
        dir.path().join("quad.obj"),
        format!(
            "v {x0} {h} {z0}\nv {x1} {h} {z0}\nv {x1} {h} {z1}\nv {x0} {h} {z1}\nf 1 2 3\nf 1 3 4\n",
            x0 = x[0],
            x1 = x[1],
            z0 = z[0],
            z1 = z[1]
        ),
    )
    .unwrap();
    let emitter = format!(
        r#"<shape type="obj"><string name="filename" value="quad.obj"/>
    <emitter type="area"><rgb name="radiance" value="{LE}, {LE}, {LE}"/></emitter></shape>"#
    );
    for target in [[0.1, -0.1], [1.0, 0.5]] {
        let want = RHO * LE * rectangle_form_factor(target[0], target[1], x, z, h);
        let got = render_floor_point(&emitter, target, 256, dir.path());
        assert_close(
            &format!("OBJ quad, floor point {target:?}"),
            got,
            want,
            0.02,
        );
    }
}

#[test]
fn sphere_light_matches_the_closed_form() {
    let dir = tempfile::tempdir().unwrap();
    // E = π Le sin²α cos θ for a sphere wholly above the horizon (α: its angular radius,
    // θ: the angle of its centre from the normal).
    let r = 0.25;
    for (h, target) in [
        (1.0, [0.0, 0.0]),
        (1.0, [0.7, 0.0]),
        (0.5, [0.0, 0.2]),
        (3.0, [1.0, 1.0]),
    ] {
        let emitter = format!(
            r#"<shape type="sphere"><point name="center" x="0" y="{h}" z="0"/>
    <float name="radius" value="{r}"/>
    <emitter type="area"><rgb name="radiance" value="{LE}, {LE}, {LE}"/></emitter></shape>"#
        );
        let d2 = h * h + target[0] * target[0] + target[1] * target[1];
        let want = RHO * LE * (r * r / d2) * (h / d2.sqrt());
        let got = render_floor_point(&emitter, target, 256, dir.path());
        assert_close(
            &format!("sphere at h = {h}, floor point {target:?}"),
            got,
            want,
            0.02,
        );
    }
}

#[test]
fn an_emitter_without_a_bsdf_reflects_nothing() {
    // A floor point lit only by light reflected off an emitter's front: the emitter faces
    // down, the floor under it is lit, and a second, unlit rectangle light facing the floor
    // point must add nothing (Mitsuba gives emitters without a BSDF a black diffuse one).
    let dir = tempfile::tempdir().unwrap();
    let alone = render_floor_point(&rectangle_emitter(0.2, 0.5), [0.0, 0.0], 128, dir.path());
    let dark_neighbour = r#"<shape type="rectangle">
    <transform name="to_world"><scale value="3"/><rotate x="1" angle="90"/><translate y="0.8"/></transform>
    <emitter type="area"><rgb name="radiance" value="0, 0, 0"/></emitter>
  </shape>"#;
    let both = render_floor_point(
        &format!("{}\n{dark_neighbour}", rectangle_emitter(0.2, 0.5)),
        [0.0, 0.0],
        128,
        dir.path(),
    );
    for c in 0..3 {
        assert!(
            (both[c] / alone[c] - 1.0).abs() < 0.02,
            "a black emitter above the floor changed channel {c}: {} vs {}",
            both[c],
            alone[c]
        );
    }
}
