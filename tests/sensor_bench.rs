//! Runs the sensor benchmark on demand (not part of the normal suite, no timing
//! assertions): `cargo test --release --test sensor_bench -- --ignored --nocapture`.
//! `camsim bench sensor` prints the same report.

#[test]
#[ignore]
fn bench_sensor_report() {
    let b = camsim::sensor::bench_sensor().unwrap();
    println!("{b}");
}
