//! The TOML config of `medial fit`: parsed, then its values checked (paths are not resolved
//! and no file is read).
#![no_main]

use libfuzzer_sys::fuzz_target;
use medial_cli::config::Config;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(config) = Config::parse(text, std::path::Path::new("fuzz.toml")) {
        let _ = config.check();
    }
});
