// How a SUMO installation (`SUMO_HOME`) is found, in one order (docs/traffic.md, "Where SUMO is
// found"). Shared by `env/src/sumo_home/mod.rs` and `env/build.rs` through `include!`, because a
// build script cannot call the crate it builds: the build finds SUMO's headers where the running
// crate finds SUMO. Hence plain items only (no inner attributes, no `use`, std only).

/// Python printing the folder of the `sumo` package (the `eclipse-sumo` wheel; its
/// `sumo.SUMO_HOME`) without importing it: `import sumo` reads the wheel's metadata, 30-130 ms.
const SUMO_PACKAGE_PROBE: &str = "import importlib.util as u, os; s = u.find_spec('sumo'); \
                                  print(os.path.dirname(s.origin) if s and s.origin else '')";

/// Step 2: `$SUMO_HOME` when set and non-empty, taken as is (a wrong one shows up as a "not
/// found under SUMO_HOME (path)" error).
fn sumo_home_from_env() -> Option<std::path::PathBuf> {
    std::env::var_os("SUMO_HOME").filter(|h| !h.is_empty()).map(std::path::PathBuf::from)
}

/// The interpreter asked for the `sumo` package outside Python: `$PYO3_PYTHON` (the Python the
/// binding is built for), else `python3` on `PATH`.
fn sumo_home_python() -> String {
    std::env::var("PYO3_PYTHON").ok().filter(|p| !p.is_empty()).unwrap_or_else(|| "python3".into())
}

/// Step 1 outside Python: the `sumo` package's folder as `python` reports it; `None` when that
/// interpreter does not run or has no such package.
fn sumo_home_from_python(python: &str) -> Option<std::path::PathBuf> {
    let out = std::process::Command::new(python).args(["-c", SUMO_PACKAGE_PROBE]).output().ok()?;
    let home = String::from_utf8(out.stdout).ok()?;
    let home = std::path::PathBuf::from(home.trim());
    (out.status.success() && home.is_dir()).then_some(home)
}

/// The precedence: `package()` (the `sumo` package of the Python in use, the pinned
/// `eclipse-sumo`), else `$SUMO_HOME`. The package comes first because `$SUMO_HOME` cannot be
/// trusted inside a Python process: importing `libsumo` sets it to the data-only `sumo_data`
/// folder (no `bin/`, no libraries) when it is unset.
fn locate_sumo_home_with(package: impl FnOnce() -> Option<std::path::PathBuf>) -> Option<std::path::PathBuf> {
    package().or_else(sumo_home_from_env)
}
