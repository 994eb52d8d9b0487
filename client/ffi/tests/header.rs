//! `include/dyfos.h` is what cbindgen generates from this crate: the checked-in
//! header cannot drift from the library.

use std::path::Path;

#[test]
fn header_is_up_to_date() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(crate_dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_crate(crate_dir)
        .with_config(config)
        .generate()
        .expect("cbindgen generates the header")
        .write(&mut generated);
    let generated = String::from_utf8(generated).expect("UTF-8 header");
    let path = crate_dir.join("include/dyfos.h");
    if std::env::var_os("DYFOS_BLESS_HEADER").is_some() {
        std::fs::write(&path, &generated).expect("write include/dyfos.h");
    }
    let checked_in = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        checked_in == generated,
        "include/dyfos.h differs from what cbindgen generates from src/; if the API change is intended, run \
         `DYFOS_BLESS_HEADER=1 cargo test -p dyfos-ffi --test header` and commit the header"
    );
    for name in [
        "dyfos_client_connect",
        "dyfos_client_rendezvous",
        "dyfos_client_list_maps",
        "dyfos_map_info",
        "DYFOS_MAX_MAPS",
        "DYFOS_STATUS_PANIC",
        "DYFOS_PARAM_LAMBDA",
    ] {
        assert!(generated.contains(name), "{name} is missing from the header");
    }
}
