//! The `fieldprobe` command-line tool (commissioning tool). The logic lives in the library; this
//! binary parses arguments, reads files and prints.

mod cli;

fn main() {
    // Opt-in diagnostics on stderr, e.g. `FIELDPROBE_LOG=debug` or `FIELDPROBE_LOG=fieldprobe::axis=trace`.
    if let Ok(filter) = tracing_subscriber::EnvFilter::try_from_env("FIELDPROBE_LOG") {
        tracing_subscriber::fmt()
            .with_env_filter(filter)
            .with_writer(|| LogWriter)
            .with_ansi(colour_on_stderr())
            .without_time()
            .init();
    }
    std::process::exit(cli::main());
}

/// Colour (ANSI escape sequences) in the log: only on a terminal, and not when `NO_COLOR` is
/// set to anything but the empty string (<https://no-color.org>).
fn colour_on_stderr() -> bool {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none_or(|v| v.is_empty())
}

/// stderr for the log: a progress line of `run` is erased before a log line is written.
struct LogWriter;

impl std::io::Write for LogWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        cli::clear_progress();
        std::io::stderr().write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        cli::clear_progress();
        std::io::stderr().write_all(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}
