//! Embeds the standard library (stdlib/shaders/*.sl, stdlib/include/*) into the binary so
//! `arbor render` works from any directory, and exports the binary's C RI functions (`Ri*`,
//! src/scene/ri_api.rs) so `Procedural "DynamicLoad"` libraries can call back into it.
use std::{env, fs, path::Path};

fn main() {
    let out = Path::new(&env::var("OUT_DIR").unwrap()).join("stdlib.rs");
    let mut code = String::new();
    for (dir, var) in [
        ("stdlib/shaders", "SHADERS"),
        ("stdlib/include", "INCLUDES"),
    ] {
        println!("cargo:rerun-if-changed={dir}");
        let mut files: Vec<_> = fs::read_dir(dir)
            .map(|r| {
                r.filter_map(|e| e.ok())
                    .map(|e| e.path())
                    .filter(|p| p.is_file())
                    .collect()
            })
            .unwrap_or_default();
        files.sort();
        code.push_str(&format!("pub static {var}: &[(&str, &str)] = &[\n"));
        for f in files {
            let name = f.file_name().unwrap().to_string_lossy().to_string();
            let abs = fs::canonicalize(&f).unwrap();
            println!("cargo:rerun-if-changed={}", f.display());
            code.push_str(&format!(
                "    ({:?}, include_str!({:?})),\n",
                name,
                abs.display().to_string()
            ));
        }
        code.push_str("];\n");
    }
    fs::write(out, code).unwrap();

    // Only the `Ri*` C functions go in the binary's dynamic symbol table (not every Rust
    // symbol, as plain -rdynamic would).
    if env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("linux") {
        let list = Path::new(&env::var("OUT_DIR").unwrap()).join("ri-exports.list");
        fs::write(&list, "{\n  Ri*;\n};\n").unwrap();
        println!(
            "cargo:rustc-link-arg-bins=-Wl,--dynamic-list={}",
            list.display()
        );
    }
}
