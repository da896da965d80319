//! Builds the SUMO shims (`sumo_shim/dh_sumo_shim.cpp`) into `OUT_DIR`: `_dh_sumo_shim.so`
//! against libsumo (SUMO in this process) and `_dh_sumo_traci.so` against libtraci (SUMO as a
//! subprocess over TraCI). `world::sumo::shim` loads them at runtime; their folder reaches this
//! crate as `DH_SUMO_SHIM_DIR` and dependents' build scripts as `DEP_DH_SUMO_SHIM_DIR` (the
//! Python binding copies them into its package).
//!
//! SUMO's C++ headers and client libraries come from the `eclipse-sumo` wheel, found as
//! `dh_env::sumo_home` finds it at run time: the `sumo` package of the build's Python
//! (`$PYO3_PYTHON`, else `python3`), else `$SUMO_HOME`. Without them (or
//! without a C++ compiler) the build still succeeds, without the shims: SUMO mode then needs
//! the Python `libsumo` transport. Nothing links SUMO.

use std::path::{Path, PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=sumo_shim/dh_sumo_shim.cpp");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=src/sumo_home/locate.rs");
    println!("cargo:rerun-if-env-changed=SUMO_HOME");
    println!("cargo:rerun-if-env-changed=PYO3_PYTHON");
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("linux") {
        // The shim is ELF/dlopen-specific.
        return;
    }
    let Some(home) = sumo_home() else {
        println!(
            "cargo:warning=SUMO headers not found (no SUMO_HOME, no `sumo` package): SUMO shims not built"
        );
        return;
    };
    let include = home.join("include");
    let lib = home.join("lib64");
    let out_dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    let mut built = false;
    for (file, library, define) in
        [("_dh_sumo_shim.so", "sumocpp", None), ("_dh_sumo_traci.so", "tracicpp", Some("DH_LIBTRACI"))]
    {
        if !include.join("libsumo").join("libsumo.h").is_file()
            || !lib.join(format!("lib{library}.so")).is_file()
        {
            println!(
                "cargo:warning=SUMO at {} has no libsumo headers or lib{library}.so: {file} not built",
                home.display()
            );
            continue;
        }
        match build(&include, &lib, library, define, &out_dir.join(file)) {
            Ok(()) => built = true,
            Err(e) => println!("cargo:warning={file} not built: {e}"),
        }
    }
    if built {
        println!("cargo:rustc-env=DH_SUMO_SHIM_DIR={}", out_dir.display());
        println!("cargo:dir={}", out_dir.display());
    }
}

// The workspace's one `SUMO_HOME` lookup (`SumoHome::locate`'s steps); a build script cannot
// call the crate it builds.
include!("src/sumo_home/locate.rs");

fn sumo_home() -> Option<PathBuf> {
    locate_sumo_home_with(|| sumo_home_from_python(&sumo_home_python()))
}

fn build(include: &Path, lib: &Path, library: &str, define: Option<&str>, dest: &Path) -> Result<(), String> {
    let src = Path::new("sumo_shim").join("dh_sumo_shim.cpp");
    // `cc` picks the C++ compiler (CXX, target flags); we link a shared object ourselves.
    let compiler =
        cc::Build::new().cpp(true).cargo_metadata(false).try_get_compiler().map_err(|e| e.to_string())?;
    let mut cmd = compiler.to_command();
    cmd.args(["-std=c++17", "-O2", "-fPIC", "-shared", "-fvisibility=hidden", "-fvisibility-inlines-hidden"]);
    if let Some(d) = define {
        cmd.arg(format!("-D{d}"));
    }
    cmd.arg("-I")
        .arg(include)
        .arg(&src)
        .arg("-L")
        .arg(lib)
        // By soname: at runtime dh-env loads the library by path first, then the shim.
        .arg(format!("-l{library}"))
        .arg("-o")
        .arg(dest);
    let out = cmd.output().map_err(|e| format!("cannot run the C++ compiler: {e}"))?;
    if !out.status.success() {
        let stderr = String::from_utf8_lossy(&out.stderr);
        let first: Vec<&str> = stderr.lines().take(5).collect();
        return Err(format!("the C++ compiler failed: {}", first.join(" | ")));
    }
    Ok(())
}
