//! The `fieldprobe` command-line tool (commissioning tool). The logic lives in the library; this
//! binary parses arguments, reads files and prints.

mod cli;

fn main() {
    // Opt-in diagnostics on stderr, e.g. `FIELDPROBE_LOG=debug` or `FIELDPROBE_LOG=fieldprobe::axis=trace`.
    if let Ok(filter) = tracing_subscriber::EnvFilter::try_from_env("FIELDPROBE_LOG") {
        tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(std::io::stderr)
            .without_time()
            .init();
    }
    std::process::exit(cli::main());
}
