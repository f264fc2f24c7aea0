//! The `progmo` binary: the command line of [`progmo::cli`] (exit codes documented there).
fn main() -> std::process::ExitCode {
    progmo::interrupt::ignore_file_size_signal();
    std::process::ExitCode::from(progmo::cli::run(std::env::args_os()))
}
