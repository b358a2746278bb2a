//! `thinfilm bench render --effects`: what each bit of physical accuracy costs in time.
//!
//! Renders the same scene (the teapot of `scenes/teapot_mgf2_400.xml` in the studio
//! environment) with only its material swapped — diffuse, smooth conductor, one Airy film
//! (constant and textured thickness), the same film and gold seen through an S polariser
//! (polarised integrator), multilayer stacks (2 and 13 layers, transfer-matrix
//! method), a free-standing film (bubble: reflection and transmission), AR-coated glass, and glass with a
//! constant or a dispersive index — plus the prism scene with its Sellmeier glass against the
//! same glass at constant index. Every variant uses the same resolution, spp, seed and thread
//! count; the time excludes BVH/light setup. Prints a markdown table of microseconds per
//! camera sample, the ratio to the diffuse baseline, Mrays/s, and the work counters that
//! show which machinery ran (thin-film evaluations, secondary-wavelength terminations).

use anyhow::{Context, Result};
use std::path::Path;
use thinfilm::render::{prepare, render_prepared, RenderOptions};
use thinfilm::scene::mitsuba::load_str;

/// `bench render` flags of this mode (flattened into its arguments).
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Instead of the Mitsuba comparison: the time cost of each effect (interference, stacks,
    /// bubbles, thickness maps, dispersion) on and off on the same scene.
    #[arg(long)]
    pub effects: bool,
    /// Samples per pixel for --effects.
    #[arg(long, default_value_t = 16)]
    pub effects_spp: u32,
    /// Square image size for --effects.
    #[arg(long, default_value_t = 128)]
    pub effects_res: u32,
}

/// What `run` needs from `bench render`'s arguments.
pub struct EffectsArgs<'a> {
    pub root: &'a Path,
    pub spp: u32,
    pub resolution: u32,
    pub seed: u64,
    pub threads: Option<usize>,
    pub table: Option<&'a Path>,
}

impl Args {
    /// Runs the effect benchmark with the shared `bench render` options.
    pub fn run(
        &self,
        root: &Path,
        seed: u64,
        threads: Option<usize>,
        table: Option<&Path>,
    ) -> Result<()> {
        anyhow::ensure!(
            self.effects_spp > 0 && self.effects_res > 0,
            "--effects-spp and --effects-res must be ≥ 1"
        );
        run(&EffectsArgs {
            root,
            spp: self.effects_spp,
            resolution: self.effects_res,
            seed,
            threads,
            table,
        })
    }
}

const TEAPOT_BSDF: &str = r#"<bsdf type="thinfilm">
            <float name="film_ior" value="1.37"/>
            <float name="thickness" value="400"/>
            <float name="substrate_ior" value="1.64"/>
            <float name="substrate_k" value="0"/>
        </bsdf>"#;

const THICKNESS_MAP: &str = r#"<texture type="bitmap" name="thickness">
                <string name="filename" value="textures/thickness_example.exr"/>
                <boolean name="raw" value="true"/>
            </texture>"#;

/// The sensor element of the teapot scenes (a sensor polariser is added after it).
const SENSOR: &str = r#"<sensor type="perspective">"#;

/// (label, effect switched on, scene file, text to replace, replacement).
fn variants() -> Vec<(String, &'static str, &'static str, String, String)> {
    let teapot = |label: &str, effect: &'static str, bsdf: String| {
        (
            label.to_string(),
            effect,
            "teapot_mgf2_400.xml",
            TEAPOT_BSDF.to_string(),
            bsdf,
        )
    };
    let glass_spheres = |v: &str| format!(r#"<default name="glass" value="{v}"/>"#);
    let prism_default = r#"<default name="glass" value="sellmeier:1.73759695,0.013188707,0.313747346,0.0623068142,1.89878101,155.23629"/>"#;
    vec![
        teapot(
            "diffuse (baseline)",
            "none",
            r#"<bsdf type="diffuse"/>"#.into(),
        ),
        teapot(
            "smooth conductor (Au)",
            "none (tabulated Fresnel)",
            r#"<bsdf type="conductor"><string name="material" value="Au"/></bsdf>"#.into(),
        ),
        teapot("thin film 400 nm", "interference", TEAPOT_BSDF.into()),
        teapot(
            "thin film, thickness map",
            "interference + texture",
            format!(
                r#"<bsdf type="thinfilm"><float name="film_ior" value="1.37"/>{THICKNESS_MAP}<float name="substrate_ior" value="1.64"/></bsdf>"#
            ),
        ),
        (
            "thin film 400 nm, S polariser".into(),
            "interference + polarisation",
            "teapot_mgf2_400.xml",
            SENSOR.into(),
            format!(r#"{SENSOR}<string name="polarizer" value="s"/>"#),
        ),
        (
            "smooth conductor (Au), S polariser".into(),
            "polarisation (Mueller Fresnel)",
            "teapot_gold.xml",
            SENSOR.into(),
            format!(r#"{SENSOR}<string name="polarizer" value="s"/>"#),
        ),
        // glTF metallic-roughness against the plastic it generalises (gltf branch).
        teapot(
            "roughplastic α=0.25",
            "none (diffuse under a GGX coating)",
            r#"<bsdf type="roughplastic"><string name="distribution" value="ggx"/><float name="alpha" value="0.25"/><rgb name="diffuse_reflectance" value="0.5, 0.5, 0.5"/></bsdf>"#.into(),
        ),
        teapot(
            "glTF PBR dielectric α=0.25",
            "glTF layers (exact Fresnel)",
            r#"<bsdf type="gltf_pbr"><rgb name="base_color" value="0.5, 0.5, 0.5"/><float name="metallic" value="0"/><float name="roughness" value="0.5"/></bsdf>"#.into(),
        ),
        teapot(
            "glTF PBR dielectric + iridescence",
            "glTF layers + interference",
            r#"<bsdf type="gltf_pbr"><rgb name="base_color" value="0.5, 0.5, 0.5"/><float name="metallic" value="0"/><float name="roughness" value="0.5"/><float name="iridescence" value="1"/></bsdf>"#.into(),
        ),
        teapot(
            "rough thin film α=0.15",
            "interference + microfacet",
            r#"<bsdf type="thinfilm"><float name="alpha" value="0.15"/></bsdf>"#.into(),
        ),
        teapot(
            "stack MgF2:100, TiO2:50",
            "TMM stack (2 layers)",
            r#"<bsdf type="thinfilm"><string name="layers" value="MgF2:100, TiO2:50"/><string name="substrate_ior" value="PET"/></bsdf>"#.into(),
        ),
        teapot(
            "stack (TiO2/SiO2)^6 TiO2",
            "TMM stack (13 layers)",
            r#"<bsdf type="thinfilm"><string name="layers" value="(TiO2:51.9, SiO2:94.2)x6, TiO2:51.9"/><string name="substrate_ior" value="BK7"/></bsdf>"#.into(),
        ),
        teapot(
            "bubble 400 nm",
            "free-standing film (R+T), Fresnel splitting",
            r#"<bsdf type="thinfilm_bubble"><float name="film_ior" value="1.33"/><float name="thickness" value="400"/></bsdf>"#.into(),
        ),
        teapot(
            "bubble, thickness map",
            "free-standing film + texture, Fresnel splitting",
            format!(r#"<bsdf type="thinfilm_bubble"><float name="film_ior" value="1.33"/>{THICKNESS_MAP}</bsdf>"#),
        ),
        teapot(
            "glass n=1.5168",
            "Fresnel splitting (refraction)",
            r#"<bsdf type="dielectric"><float name="int_ior" value="1.5168"/></bsdf>"#.into(),
        ),
        teapot(
            "AR-coated glass n=1.5168",
            "TMM stack on a refracting interface, Fresnel splitting",
            r#"<bsdf type="coateddielectric"><float name="int_ior" value="1.5168"/><string name="coating" value="MgF2:99.6"/></bsdf>"#.into(),
        ),
        teapot(
            "glass material:BK7",
            "dispersion",
            r#"<bsdf type="dielectric"><string name="int_ior" value="material:BK7"/></bsdf>"#.into(),
        ),
        (
            "prism SF11 n=1.7847".into(),
            "Fresnel splitting (refraction)",
            "prism.xml",
            prism_default.into(),
            glass_spheres("1.7847"),
        ),
        (
            "prism SF11 Sellmeier".into(),
            "dispersion",
            "prism.xml",
            prism_default.into(),
            prism_default.into(),
        ),
    ]
}

pub fn run(args: &EffectsArgs) -> Result<()> {
    let scenes = args.root.join("scenes");
    let mut rows = Vec::new();
    let mut baseline = None;
    for (label, effect, file, from, to) in variants() {
        let path = scenes.join(file);
        let text = std::fs::read_to_string(&path)
            .with_context(|| format!("reading {}", path.display()))?;
        anyhow::ensure!(
            text.contains(&from),
            "{}: the material block this benchmark swaps is not in the scene any more",
            path.display()
        );
        let text = text.replace(&from, &to);
        let scene = load_str(&text, &scenes, &[], &format!("{file} [{label}]"))?;
        let options = RenderOptions {
            spp: Some(args.spp),
            seed: Some(args.seed),
            threads: args.threads,
            resolution: Some((args.resolution, args.resolution)),
            // The cost of a camera sample of each material, not where the samples go.
            uniform_samples: true,
            ..Default::default()
        };
        let prepared = prepare(&scene, &options)?;
        let out = render_prepared(&prepared, &options)?;
        let s = &out.stats;
        let samples = s.samples.max(1) as f64;
        let us_per_sample = s.seconds / samples * 1e6;
        let base = *baseline.get_or_insert(us_per_sample);
        let terminations = s.secondary_terminations as f64 / samples;
        eprintln!("{label}: {:.3} s", s.seconds);
        rows.push(format!(
            "| {label} | {effect} | {us_per_sample:.3} | {:.2}× | {:.2} | {:.2} | {:.3} |",
            us_per_sample / base,
            s.rays_per_second() / 1e6,
            s.film_evals as f64 / samples,
            terminations,
        ));
    }
    let mut table = format!(
        "Effect cost: {r}×{r}, {spp} spp, seed {seed}, {threads} thread(s); render time without setup.\n\n\
         | material | effect switched on | µs / sample | vs diffuse | Mrays/s | film evals / sample | secondary terminations / sample |\n\
         |---|---|---:|---:|---:|---:|---:|\n",
        r = args.resolution,
        spp = args.spp,
        seed = args.seed,
        threads = args
            .threads
            .map_or_else(|| rayon::current_num_threads().to_string(), |t| t.to_string()),
    );
    for r in &rows {
        table.push_str(r);
        table.push('\n');
    }
    println!("{table}");
    if let Some(p) = args.table {
        thinfilm::image_io::write_atomically(p, |tmp| {
            std::fs::write(tmp, table.as_bytes())?;
            Ok(())
        })
        .with_context(|| format!("writing {}", p.display()))?;
    }
    Ok(())
}
