//! The `jderobot` binary: a thin shell over [`jderobot::cli::main`].
fn main() -> std::process::ExitCode {
    jderobot::cli::main()
}
