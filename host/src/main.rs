//! `imucal` command-line tool.
fn main() {
    eprintln!("imucal: no commands yet");
    std::process::exit(2);
}
