//! Parser throughput on a generated trianglemesh file (the body of `camsim bench parse`).
//! Usage: cargo run --release --example pbrt_parse_bench [SIZE_MB]
fn main() {
    let mb: f64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(100.0);
    match camsim::scene::pbrt::bench::run_parse_benchmark(mb) {
        Ok(r) => println!("{}", serde_json::to_string_pretty(&r).unwrap_or_default()),
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(3);
        }
    }
}
