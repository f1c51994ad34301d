//! The `fieldprobe` command-line tool (commissioning tool). The logic lives in the library; this
//! binary parses arguments, reads files and prints.

mod cli;

fn main() {
    std::process::exit(cli::main());
}
