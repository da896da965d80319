//! Builds the native SUMO backend's shim (`sumo_shim/dh_sumo_shim.cpp`) into
//! `drivehierarchy/_dh_sumo_shim.so`, beside `_core`, so editable installs and wheels carry it.
//!
//! SUMO's C++ headers and `libsumocpp.so` come from the `eclipse-sumo` wheel: `$SUMO_HOME`, else
//! the `sumo` package of the build's Python (`$PYO3_PYTHON`, else `python3`). Without them (or
//! without a C++ compiler) the build still succeeds: the shim is missing and SUMO mode falls back
//! to the Python libsumo backend at runtime. The core itself never links SUMO.

use std::path::{Path, PathBuf};
use std::process::Command;

const SHIM: &str = "_dh_sumo_shim.so";

fn main() {
    println!("cargo:rerun-if-changed=sumo_shim/dh_sumo_shim.cpp");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=SUMO_HOME");
    println!("cargo:rerun-if-env-changed=PYO3_PYTHON");
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("linux") {
        // The shim is ELF/dlopen-specific; other platforms use the Python backend.
        return;
    }
    let Some(home) = sumo_home() else {
        println!("cargo:warning=SUMO headers not found (no SUMO_HOME, no `sumo` package): native SUMO backend not built");
        return;
    };
    let include = home.join("include");
    let lib = home.join("lib64");
    if !include.join("libsumo").join("libsumo.h").is_file() || !lib.join("libsumocpp.so").is_file() {
        println!(
            "cargo:warning=SUMO at {} has no libsumo C++ headers or libsumocpp.so: native SUMO backend not built",
            home.display()
        );
        return;
    }
    if let Err(e) = build(&include, &lib) {
        println!("cargo:warning=native SUMO backend not built: {e}");
    }
}

fn sumo_home() -> Option<PathBuf> {
    if let Some(h) = std::env::var_os("SUMO_HOME").filter(|h| !h.is_empty()) {
        return Some(PathBuf::from(h));
    }
    let python = std::env::var("PYO3_PYTHON").unwrap_or_else(|_| "python3".into());
    let out = Command::new(python).args(["-c", "import sumo; print(sumo.SUMO_HOME)"]).output().ok()?;
    let home = String::from_utf8(out.stdout).ok()?;
    let home = home.trim();
    (out.status.success() && !home.is_empty()).then(|| PathBuf::from(home))
}

fn build(include: &Path, lib: &Path) -> Result<(), String> {
    let src = Path::new("sumo_shim").join("dh_sumo_shim.cpp");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").map_err(|e| e.to_string())?);
    let built = out_dir.join(SHIM);
    // `cc` picks the C++ compiler (CXX, target flags); we link a shared object ourselves.
    let compiler =
        cc::Build::new().cpp(true).cargo_metadata(false).try_get_compiler().map_err(|e| e.to_string())?;
    let mut cmd = compiler.to_command();
    cmd.args(["-std=c++17", "-O2", "-fPIC", "-shared", "-fvisibility=hidden", "-fvisibility-inlines-hidden"])
        .arg("-I")
        .arg(include)
        .arg(&src)
        .arg("-L")
        .arg(lib)
        // By soname: at runtime the core loads libsumocpp by path first, then this shim.
        .arg("-lsumocpp")
        .arg("-o")
        .arg(&built);
    let out = cmd.output().map_err(|e| format!("cannot run the C++ compiler: {e}"))?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        let first: Vec<&str> = stderr.lines().take(5).collect();
        return Err(format!("the C++ compiler failed: {}", first.join(" | ")));
    }
    let dest = Path::new("drivehierarchy").join(SHIM);
    let tmp = Path::new("drivehierarchy").join(format!("{SHIM}.tmp"));
    std::fs::copy(&built, &tmp)
        .and_then(|_| std::fs::rename(&tmp, &dest))
        .map_err(|e| format!("{}: {e}", dest.display()))?;
    Ok(())
}
