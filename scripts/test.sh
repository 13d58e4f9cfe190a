#!/usr/bin/env bash
# Every check of the project, as CI runs it: formatting, clippy on the host
# and for the Cortex-M4F, the firmware release build with its flash/RAM use,
# and all tests. Needs only the Rust toolchain (rustup installs the target
# and components named in rust-toolchain.toml).
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }

step "toolchain (rust-toolchain.toml: stable, thumbv7em-none-eabihf, clippy, rustfmt, llvm-tools)"
rustup show active-toolchain || rustup toolchain install
rustup target add thumbv7em-none-eabihf >/dev/null
rustup component add clippy rustfmt llvm-tools >/dev/null

step "cargo fmt --check"
cargo fmt --all --check

step "clippy, host"
cargo clippy --all-targets -- -D warnings

step "clippy, thumbv7em-none-eabihf (shared + firmware)"
cargo clippy -p shared -p firmware --target thumbv7em-none-eabihf -- -D warnings

step "firmware release build"
cargo build -p firmware --release --target thumbv7em-none-eabihf
size_tool="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin/llvm-size"
"$size_tool" target/thumbv7em-none-eabihf/release/firmware | awk 'NR==2 {
  printf "firmware flash (text+data): %d B of 64 KiB budget; RAM (data+bss): %d B of 32 KiB budget\n", $1+$2, $2+$3 }'

step "tests"
cargo test --workspace --exclude firmware
