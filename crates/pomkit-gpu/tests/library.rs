//! The shader library's two forms: the plain-WGSL file in the repository is the flattened WESL
//! modules, and both validate.

use std::path::Path;

#[test]
fn plain_wgsl_file_is_the_flattened_modules() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders/pomkit.wgsl");
    let want = pomkit_gpu::library::flatten();
    if std::env::var_os("UPDATE_SHADERS").is_some() {
        std::fs::write(&path, &want).expect("write shaders/pomkit.wgsl");
    }
    let have = std::fs::read_to_string(&path).expect("shaders/pomkit.wgsl exists");
    assert!(
        have == want,
        "{} is not the flattened WESL modules: run `UPDATE_SHADERS=1 cargo test -p pomkit-gpu --test library`",
        path.display()
    );
}
