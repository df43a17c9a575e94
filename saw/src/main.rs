//! `saw --port PORT <command>`: see `saw --help` and docs/link.md.

use std::io::Write;
use std::process::ExitCode;

/// Prints a line on stdout; a reader that went away (`saw … | head`) is not an error of ours:
/// nothing is left to say to it.
fn out(line: &str) {
    let mut o = std::io::stdout().lock();
    let _ = writeln!(o, "{line}").and_then(|_| o.flush());
}

use saw::{parse_args, run, Parsed};

fn main() -> ExitCode {
    let cli = match parse_args(std::env::args_os()) {
        Parsed::Run(cli) => cli,
        // --help, --version: clap's own text, exit 0.
        Parsed::Print(text) => {
            let mut o = std::io::stdout().lock();
            let _ = write!(o, "{text}").and_then(|_| o.flush());
            return ExitCode::SUCCESS;
        }
        // A bad command line: one line, on stdout as JSON when --json was asked for.
        Parsed::Refused { json, message } => {
            if json {
                out(
                    &serde_json::json!({ "ok": false, "kind": "input", "error": message })
                        .to_string(),
                );
            } else {
                eprintln!("error: {message}");
            }
            return ExitCode::from(2);
        }
    };
    match run(&cli) {
        Ok(done) => {
            if cli.json {
                out(&serde_json::json!({ "ok": true, "result": done.json }).to_string());
            } else {
                out(&done.text);
            }
            ExitCode::SUCCESS
        }
        Err(f) => {
            if cli.json {
                out(
                    &serde_json::json!({ "ok": false, "kind": f.kind, "error": f.message })
                        .to_string(),
                );
            } else {
                eprintln!("error: {}", f.message);
            }
            ExitCode::from(f.code)
        }
    }
}
