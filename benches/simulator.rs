//! Simulator benchmark (filled in below).
fn main() {}
