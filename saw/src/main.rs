//! `saw --port PORT <command>`: see `saw --help` and docs/link.md.

use std::process::ExitCode;

use saw::{parse_args, run, Parsed};

fn main() -> ExitCode {
    let cli = match parse_args(std::env::args_os()) {
        Parsed::Run(cli) => cli,
        // --help, --version: clap's own text, exit 0.
        Parsed::Print(text) => {
            print!("{text}");
            return ExitCode::SUCCESS;
        }
        // A bad command line: one line, on stdout as JSON when --json was asked for.
        Parsed::Refused { json, message } => {
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "ok": false, "kind": "input", "error": message })
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
                println!("{}", serde_json::json!({ "ok": true, "result": done.json }));
            } else {
                println!("{}", done.text);
            }
            ExitCode::SUCCESS
        }
        Err(f) => {
            if cli.json {
                println!(
                    "{}",
                    serde_json::json!({ "ok": false, "kind": f.kind, "error": f.message })
                );
            } else {
                eprintln!("error: {}", f.message);
            }
            ExitCode::from(f.code)
        }
    }
}
