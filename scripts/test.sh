#!/usr/bin/env bash
# Every check of the project, as CI runs it: formatting, clippy on the host
# and for the Cortex-M4F, the firmware release build with its flash/RAM use,
# the processor-in-the-loop target, and all tests (PIL included). Needs only
# the Rust toolchain (rustup installs the target and components named in
# rust-toolchain.toml); installs qemu-system-arm with apt when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."

# Each step's wall time, printed at the end (also when a step fails), so
# that CI shows where the time goes.
step_names=()
step_seconds=()
step_started=$SECONDS
end_step() {
  if [ "${#step_names[@]}" -gt "${#step_seconds[@]}" ]; then
    step_seconds+=($((SECONDS - step_started)))
  fi
}
step() {
  end_step
  step_names+=("$*")
  step_started=$SECONDS
  printf '\n==> %s\n' "$*"
}
report_times() {
  local status=$?
  end_step
  printf '\n==> wall time per step%s\n' "$([ "$status" -eq 0 ] || echo " (failed, exit status $status)")"
  local i
  for i in "${!step_names[@]}"; do
    printf '%5d s  %s\n' "${step_seconds[$i]}" "${step_names[$i]}"
  done
  printf '%5d s  total\n' "$SECONDS"
}
trap report_times EXIT

step "toolchain (rust-toolchain.toml: stable, thumbv7em-none-eabihf, clippy, rustfmt, llvm-tools)"
rustup show active-toolchain || rustup toolchain install
rustup target add thumbv7em-none-eabihf >/dev/null
rustup component add clippy rustfmt llvm-tools >/dev/null

step "longest functions of the library crates (information only)"
./scripts/longest-functions.sh 15 || true

step "qemu-system-arm (processor-in-the-loop tests)"
if ! command -v qemu-system-arm >/dev/null 2>&1; then
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -q
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q qemu-system-arm
fi
qemu-system-arm --version | head -n 1

step "cargo fmt --check"
cargo fmt --all --check
cargo fmt --manifest-path pil/Cargo.toml --check

step "clippy, host"
cargo clippy --all-targets -- -D warnings

step "clippy, thumbv7em-none-eabihf (drive-core + firmware, PIL target)"
cargo clippy -p drive-core -p firmware --target thumbv7em-none-eabihf -- -D warnings
cargo clippy --manifest-path pil/Cargo.toml --release --target thumbv7em-none-eabihf -- -D warnings

step "firmware release build"
cargo build -p firmware --release --target thumbv7em-none-eabihf
size_tool="$(rustc --print sysroot)/lib/rustlib/$(rustc -vV | sed -n 's/^host: //p')/bin/llvm-size"
"$size_tool" target/thumbv7em-none-eabihf/release/firmware | awk 'NR==2 {
  printf "firmware flash (text+data): %d B of 192 KiB budget; RAM (data+bss): %d B of 64 KiB budget\n", $1+$2, $2+$3 }'

step "PIL target build (QEMU mps2-an386)"
cargo build --manifest-path pil/Cargo.toml --release --target thumbv7em-none-eabihf

step "tests"
cargo test --workspace --exclude firmware
