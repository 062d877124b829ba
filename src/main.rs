//! The `scarp` command-line tool. Run `scarp --help` for the subcommands.

use clap::Parser;

fn main() -> std::process::ExitCode {
    let cli = scarp::cli::Cli::parse();
    match scarp::cli::run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("error: {error:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
