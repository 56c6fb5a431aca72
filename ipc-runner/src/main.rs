//! `ipc-runner`: the real-time estimation loop, Monte-Carlo evaluation and the demo.

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("demo") | None => {
            println!("ipc-runner demo: not yet available (the pipeline issue adds it)");
        }
        Some(other) => {
            eprintln!("ipc-runner: unknown command {other:?}");
            std::process::exit(2);
        }
    }
}
