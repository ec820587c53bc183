//! Link settings of the FMU binary that depend on the target.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    // macOS: without an explicit install name the dylib records the absolute path it was linked
    // at on the build machine; FMI importers load it by path, so a relocatable name is enough.
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("macos") {
        println!("cargo:rustc-cdylib-link-arg=-Wl,-install_name,@rpath/QuadController.dylib");
    }
}
