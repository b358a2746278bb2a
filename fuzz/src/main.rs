//! AFL++ harness: `thinfilm-fuzz TARGET` runs the loader of one input format (the targets
//! of `fuzz/targets.rs`, shared with the in-process fuzz test) on the inputs AFL++ generates.
//! A contained panic (an error that reports one) is re-raised so AFL++ records it as a crash.
//! `thinfilm-fuzz seeds DIR` writes the valid seed inputs of every target to `DIR/TARGET/`.
//! See README.md.

#[path = "../targets.rs"]
mod targets;

use std::path::PathBuf;

const USAGE: &str =
    "usage: thinfilm-fuzz TARGET | thinfilm-fuzz seeds DIR\n  TARGET: envi-header, envi-cube, capture, xml, ply, obj, gltf, glb, exr,\n          serialized, include, image, provenance";

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scratch = std::env::temp_dir().join(format!("thinfilm-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&scratch).expect("creating a scratch folder");
    targets::prepare_assets(&scratch).expect("writing the fuzz assets");
    match args.as_slice() {
        [cmd, dir] if cmd == "seeds" => {
            for target in targets::ALL {
                let out = PathBuf::from(dir).join(target.name());
                std::fs::create_dir_all(&out).expect("creating the seed folder");
                for (k, seed) in targets::seeds(target, &scratch).iter().enumerate() {
                    std::fs::write(out.join(format!("seed{k}")), seed).expect("writing a seed");
                }
            }
        }
        [name] => {
            let target = targets::Target::from_name(name).unwrap_or_else(|| panic!("{USAGE}"));
            afl::fuzz!(|data: &[u8]| {
                if let Err(msg) = targets::run(target, data, &scratch) {
                    if msg.contains(thinfilm::limits::CONTAINED_PANIC) {
                        panic!("{msg}");
                    }
                }
            });
        }
        _ => eprintln!("{USAGE}"),
    }
}
