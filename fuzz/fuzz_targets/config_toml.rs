#![no_main]
//! The config TOML: `pedscan::config::Config::from_file`, then `Config::validate`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = pedscan_fuzz::input_file("config.toml", data);
    if let Ok(cfg) = pedscan::config::Config::from_file(&path) {
        let _ = cfg.validate();
        let _ = cfg.to_toml();
    }
});
