//! The `medial` binary: everything is in the library ([`medial_cli::main`]).

fn main() -> std::process::ExitCode {
    medial_cli::main()
}
