//! Gives `libdyfos.so` its SONAME, `libdyfos.so.<ABI version>` (src/version.rs), so
//! that programs linked against it record the ABI they need and the dynamic linker
//! refuses a library of another ABI.

#[allow(dead_code)] // Only the ABI version is needed here.
mod version {
    include!("src/version.rs");
}

fn main() {
    println!("cargo:rerun-if-changed=src/version.rs");
    if std::env::var("CARGO_CFG_TARGET_OS").is_ok_and(|os| os == "linux") {
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libdyfos.so.{}", version::DYFOS_ABI_VERSION);
    }
}
