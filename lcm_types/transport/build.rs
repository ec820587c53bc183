//! Links Debian's liblcm. `pkg-config lcm` needs libglib2.0-dev and only adds glib, which
//! liblcm.so already depends on dynamically, so linking `-llcm` directly is enough.
fn main() {
    println!("cargo:rustc-link-lib=dylib=lcm");
    println!("cargo:rerun-if-changed=build.rs");
}
