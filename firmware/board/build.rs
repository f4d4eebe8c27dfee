//! Link script set-up: the STM32G474RE memory map lives in the repository root `memory.x`;
//! copy it to OUT_DIR so the linker finds it, and pass cortex-m-rt's and defmt's scripts.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").unwrap());
    let manifest = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").unwrap());
    let src = manifest.join("../../memory.x");
    fs::copy(&src, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", src.display());
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    // Identical code folding: functions that compile to the same bytes (monomorphisations
    // over types of one layout, drop glue, closures) are kept once. Rust makes no promise
    // that distinct functions have distinct addresses, so folding all of them is sound.
    println!("cargo:rustc-link-arg-bins=--icf=all");
}
