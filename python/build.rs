//! Copies the SUMO shims that `dh-env`'s build script compiled (`env/sumo_shim/`, folder in
//! `DEP_DH_SUMO_SHIM_DIR`) into `drivehierarchy/`, beside `_core`, so editable installs and
//! wheels carry them. Without them (no SUMO headers at build time) the package has no shims and
//! SUMO mode uses the `libsumo` Python module.

use std::path::Path;

const SHIMS: [&str; 2] = ["_dh_sumo_shim.so", "_dh_sumo_traci.so"];

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=DEP_DH_SUMO_SHIM_DIR");
    let Ok(dir) = std::env::var("DEP_DH_SUMO_SHIM_DIR") else {
        return;
    };
    for shim in SHIMS {
        let built = Path::new(&dir).join(shim);
        if !built.is_file() {
            continue;
        }
        println!("cargo:rerun-if-changed={}", built.display());
        let dest = Path::new("drivehierarchy").join(shim);
        let tmp = Path::new("drivehierarchy").join(format!("{shim}.tmp"));
        if let Err(e) = std::fs::copy(&built, &tmp).and_then(|_| std::fs::rename(&tmp, &dest)) {
            println!("cargo:warning=cannot copy the SUMO shim to {}: {e}", dest.display());
        }
    }
}
