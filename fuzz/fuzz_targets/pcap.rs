#![no_main]
//! The `pcap` target: `pedscan_fuzz::pcap` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::pcap(data));
