//! The `hytask` binary: a thin shell over [`hytask::cli`].

fn main() -> std::process::ExitCode {
    hytask::cli::main()
}
