fn main() { println!("{}", pedscan::version()); }
