//! Inputs that crashed or hung a fuzz target (`fuzz/`, docs/fuzzing.md), replayed by every
//! `cargo test`: each must give a value or an error, without panicking, and stay bounded.
//! Files live in `tests/fuzz_regressions/<target>/`.

use dh_env::map::Network;
use std::path::{Path, PathBuf};

fn inputs(target: &str) -> Vec<(PathBuf, String)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fuzz_regressions").join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "no inputs in {}", dir.display());
    files.into_iter().map(|f| (f.clone(), std::fs::read_to_string(&f).unwrap())).collect()
}

/// `.net.xml` inputs (target `net_xml`).
///
/// - `timeout-far_vertex_grid`: one lane vertex 5e97 m away made the drivable-area grid's long
///   side ~1e50 cells (only the total was capped), so building it never ended.
#[test]
fn net_xml() {
    for (path, text) in inputs("net_xml") {
        match Network::from_xml_str(&path, &text) {
            Ok(net) => {
                let (_, _, cells, _) = net.drivable().stats();
                assert!(cells <= 2_100_000, "{}: grid of {cells} cells", path.display());
            }
            Err(e) => assert!(e.to_string().contains(&*path.to_string_lossy()), "{}: {e}", path.display()),
        }
    }
}
