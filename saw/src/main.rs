//! `saw --port PORT <command>`: see `saw --help` and docs/link.md.

use std::process::ExitCode;

use clap::Parser;
use saw::{run, Cli};

fn main() -> ExitCode {
    let cli = Cli::parse();
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
