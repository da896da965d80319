//! `cargo run -p dh-env --example validate_scenario -- FILE...`: what
//! `drivehierarchy scenario validate FILE` prints, until the CLI wires `dh_env::scenario::validate`.

fn main() {
    let mut failed = false;
    for f in std::env::args().skip(1) {
        match dh_env::scenario::validate(&f) {
            Ok(s) => println!("{s}"),
            Err(e) => {
                failed = true;
                eprintln!("error: {e}");
            }
        }
    }
    if failed {
        std::process::exit(1);
    }
}
