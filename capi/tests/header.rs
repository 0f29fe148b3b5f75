//! The committed header `capi/include/skinfield.h` is what cbindgen makes of the crate today.
//! After changing the C API, regenerate it with
//! `SKINFIELD_BLESS=1 cargo test -p skinfield-capi --test header`.

use std::path::Path;

#[test]
fn committed_header_is_up_to_date() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(crate_dir.join("cbindgen.toml")).unwrap();
    let mut generated = Vec::new();
    cbindgen::Builder::new()
        .with_crate(crate_dir)
        .with_config(config)
        .generate()
        .expect("cbindgen could not parse the crate")
        .write(&mut generated);
    let path = crate_dir.join("include/skinfield.h");
    if std::env::var_os("SKINFIELD_BLESS").is_some() {
        std::fs::write(&path, &generated).unwrap();
        return;
    }
    let committed = std::fs::read(&path).unwrap_or_default();
    assert!(
        committed == generated,
        "{} is out of date: regenerate it with \
         `SKINFIELD_BLESS=1 cargo test -p skinfield-capi --test header`",
        path.display()
    );
}
