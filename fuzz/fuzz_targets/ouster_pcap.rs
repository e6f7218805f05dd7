#![no_main]
//! The `ouster_pcap` target: `pedscan_fuzz::ouster_pcap` (fuzz/src/lib.rs) says what it reads.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| pedscan_fuzz::ouster_pcap(data));
