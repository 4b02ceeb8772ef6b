fn main() { eprintln!("rt-controller: not implemented yet (issue 5)"); std::process::exit(2); }
