//! Compiles the colour tables in `spectra/` into Rust arrays (filled by the foundation work).
fn main() {
    println!("cargo:rerun-if-changed=spectra");
}
