#!/usr/bin/env bash
# The control step on an emulated Cortex-M4 (QEMU mps2-an386):
#  1. bit identity: the host and the Cortex-M4 replay the same recorded 12,000-step input
#     sequence (vectors.bin) and must print the same digest of every output;
#  2. instructions per current-loop step (../../shared/tools/qemu-insn), printed;
#  3. flash and static RAM of the release board image, printed (when it has been built).
# Needs qemu-system-arm and gcc (Debian packages). Fails only on a digest mismatch or a
# broken build; the speed and size figures are printed against their targets.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
bin="$(rustc --print sysroot)/lib/rustlib/x86_64-unknown-linux-gnu/bin"
export PATH="$bin:$PATH"

host=$(cd "$root" && cargo run -q --release -p regen-fw --example digest -- "$here/vectors.bin")
# The digest line an ELF prints on the emulated Cortex-M4.
m4_digest() {
  timeout 300 qemu-system-arm -M mps2-an386 -cpu cortex-m4 -nographic -monitor none \
    -semihosting-config enable=on,target=native -kernel "$1" | tr -d '\r' | grep '^digest='
}
(cd "$here" && cargo build -q --release)
elf="$here/target/thumbv7em-none-eabihf/release/regen-m4check"
m4=$(m4_digest "$elf")
echo "host:      $host"
echo "cortex-m4: $m4"
if [ "$host" != "$m4" ]; then
  echo "FAIL: the Cortex-M4 outputs differ from the host's" >&2
  exit 1
fi
# The step as the board image builds it (firmware/board/Cargo.toml: every package at
# opt-level "z", for flash): the same source, checked for bit identity too, counted below.
zdir="$here/target/board-profile"
(cd "$here" && cargo build -q --release --target-dir "$zdir" \
  --config 'profile.release.opt-level="z"' --config 'profile.release.package."*".opt-level="z"')
zelf="$zdir/thumbv7em-none-eabihf/release/regen-m4check"
if [ "$host" != "$(m4_digest "$zelf")" ]; then
  echo "FAIL: the board-profile Cortex-M4 outputs differ from the host's" >&2
  exit 1
fi
echo "bit identity: OK (opt-level 3 and the board's opt-level z)"

tools=${QEMU_INSN_TOOLS:-"$root/../shared/tools/qemu-insn"}
if [ -x "$tools/count.sh" ] || [ -f "$tools/count.sh" ]; then
  line=$(timeout 300 sh "$tools/count.sh" "$elf" regen_step 2>&1 | grep insnwin | tail -n1)
  echo "$line"
  max=$(echo "$line" | sed -n 's/.*max=\([0-9]*\).*/\1/p')
  min=$(echo "$line" | sed -n 's/.*min=\([0-9]*\).*/\1/p')
  echo "instructions per current-loop step: min $min, max $max (target: at most 400)"
  rline=$(timeout 300 sh "$tools/count.sh" "$elf" regen_step_refresh 2>&1 | grep insnwin | tail -n1)
  echo "instructions on a step serving a refresh request itself (law_mut; none in the recorded run, counted on copies): min $(echo "$rline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$rline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')"
  cline=$(timeout 300 sh "$tools/count.sh" "$elf" regen_set_config 2>&1 | grep insnwin | tail -n1)
  echo "instructions of the run's configuration change done at once (set_config, as the console's copy does it: validation, gains, slow terms): $(echo "$cline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')"
  kline=$(timeout 300 sh "$tools/count.sh" "$elf" regen_compile 2>&1 | grep insnwin | tail -n1)
  iline=$(timeout 300 sh "$tools/count.sh" "$elf" regen_install 2>&1 | grep insnwin | tail -n1)
  echo "the same change as the loop takes it: compiled in the console's task $(echo "$kline" | sed -n 's/.*max=\([0-9]*\).*/\1/p'), swapped in between two periods by that task with the loop locked $(echo "$iline" | sed -n 's/.*max=\([0-9]*\).*/\1/p') (the interrupt serves none)"
  sline=$(timeout 300 sh "$tools/count.sh" "$elf" regen_supervise 2>&1 | grep insnwin | tail -n1)
  echo "$sline"
  echo "instructions per protection supervision tick (1 kHz, outside the step): min $(echo "$sline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$sline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')"
  # The distribution over the recorded run (the counter prints every call with verbose=1).
  plug=${TMPDIR:-/tmp}/libinsnwin.so
  nm=$(command -v rust-nm || command -v llvm-nm || command -v nm)
  addr=$($nm "$elf" | awk '$3=="regen_step" {print "0x"$1}' | head -n1)
  timeout 300 qemu-system-arm -M mps2-an386 -cpu cortex-m4 -nographic -monitor none \
    -semihosting-config enable=on,target=native -icount shift=0 \
    -plugin "$plug,func=$addr,verbose=1" -d plugin -kernel "$elf" 2>&1 |
    awk '/insnwin: #/ {print $3}' | sort -n |
    awk '{a[NR]=$1} END {printf "distribution over %d steps: p10 %d, median %d, p90 %d\n", NR, a[int(NR*0.1)], a[int(NR/2)], a[int(NR*0.9)]}'
  # Pieces, each counted alone on the same run (a call and its arguments included).
  for f in piece_encoder piece_sin_cos piece_rotate piece_park piece_inverse_park piece_pi piece_svpwm piece_gain; do
    p=$(timeout 300 sh "$tools/count.sh" "$elf" "$f" 2>&1 | grep insnwin | tail -n1 |
      sed -n 's/.*min=\([0-9]*\) max=\([0-9]*\).*/\1–\2/p')
    echo "  $f: $p"
  done
  zline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_step 2>&1 | grep insnwin | tail -n1)
  echo "instructions per current-loop step as the board builds it (opt-level z, bit identity OK): min $(echo "$zline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$zline" | sed -n 's/.*max=\([0-9]*\).*/\1/p') (target: at most 400)"
  bline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_step_boot 2>&1 | grep insnwin | tail -n1)
  echo "instructions per power-up step (offset calibration, alignment, its faults; not the commissioning measurement, counted below) as the board builds it: min $(echo "$bline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$bline" | sed -n 's/.*max=\([0-9]*\).*/\1/p') (target: at most 400)"
  bline=$(timeout 300 sh "$tools/count.sh" "$elf" regen_step_boot 2>&1 | grep insnwin | tail -n1)
  echo "instructions per power-up step at opt-level 3: min $(echo "$bline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$bline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')"
  cline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_cap_record 2>&1 | grep insnwin | tail -n1)
  capmax=$(echo "$cline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')
  echo "instructions of the capture's sample (cap armed, after the outputs are written: Period::finish -> Capture::record; the worst over channel sets and trigger kinds: four channels with a level trigger on ia firing, a fault, a command and a level trigger on p with four, one channel with a level trigger on vbus; each armed again once full) as the board builds it: min $(echo "$cline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $capmax"
  cline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_cap_record_iq 2>&1 | grep insnwin | tail -n1)
  echo "  the same for a load step's channels (iq, iq_ref, trigger cmd): $(echo "$cline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')"
  pline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_period_power 2>&1 | grep insnwin | tail -n1)
  echo "the period's electrical power for its energy sum (every period, before the step; after the outputs while a capture is armed, then shared with it) as the board builds it: min $(echo "$pline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$pline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')"
  cline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_step_cap 2>&1 | grep insnwin | tail -n1)
  echo "instructions per current-loop step with the capture armed (the step to its outputs and that sample, counted together) as the board builds it: min $(echo "$cline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$cline" | sed -n 's/.*max=\([0-9]*\).*/\1/p') (target: at most 400)"
  zaddr=$($nm "$zelf" | awk '$3=="regen_step_cap" {print "0x"$1}' | head -n1)
  timeout 300 qemu-system-arm -M mps2-an386 -cpu cortex-m4 -nographic -monitor none \
    -semihosting-config enable=on,target=native -icount shift=0 \
    -plugin "$plug,func=$zaddr,verbose=1" -d plugin -kernel "$zelf" 2>&1 |
    awk '/insnwin: #/ {n++; if ($3 > 400) o++} END {printf "  of its %d counted calls %d (%.0f %%) above 400\n", n, o, 100 * o / n}'
  zmax=$(echo "$zline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')
  echo "  the step's worst and the sample's worst added (whether or not they meet in the replay): $((zmax + capmax))"
  mline=$(timeout 600 sh "$tools/count.sh" "$zelf" regen_step_measure 2>&1 | grep insnwin | tail -n1)
  echo "instructions per commissioning period (measure: its own loop in f32, not the running step) as the board builds it: min $(echo "$mline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$mline" | sed -n 's/.*max=\([0-9]*\).*/\1/p') (a period is 8,500 cycles at 170 MHz)"
  tline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_step_trip 2>&1 | grep insnwin | tail -n1)
  echo "instructions per current-loop step that finds an instantaneous fault (over-current or over-voltage: the fault and its safe mode in force, the outputs safe) as the board builds it: min $(echo "$tline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$tline" | sed -n 's/.*max=\([0-9]*\).*/\1/p') (target: at most 400)"
  tline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_step_trip2 2>&1 | grep insnwin | tail -n1)
  echo "  both in one period (over-current and over-voltage): min $(echo "$tline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$tline" | sed -n 's/.*max=\([0-9]*\).*/\1/p') (target: at most 400)"
  fline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_trip_finish 2>&1 | grep insnwin | tail -n1)
  echo "the rest of that latch after the outputs are written (record with its snapshot, PI reset, slow terms; Period::finish) as the board builds it: min $(echo "$fline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$fline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')"
  fline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_trip_finish2 2>&1 | grep insnwin | tail -n1)
  echo "  for both faults in one period: min $(echo "$fline" | sed -n 's/.*min=\([0-9]*\).*/\1/p'), max $(echo "$fline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')"
  iline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_install 2>&1 | grep insnwin | tail -n1)
  echo "the configuration swap between two periods (the console task's critical section) as the board builds it: $(echo "$iline" | sed -n 's/.*max=\([0-9]*\).*/\1/p')"
  wline=$(timeout 300 sh "$tools/count.sh" "$zelf" regen_step_swapped 2>&1 | grep insnwin | tail -n1)
  echo "instructions per current-loop step right after that swap as the board builds it: $(echo "$wline" | sed -n 's/.*max=\([0-9]*\).*/\1/p') (target: at most 400)"
else
  echo "instruction count skipped: $tools not found"
fi

board="$root/firmware/board/target/thumbv7em-none-eabihf/release"
img=$(ls "$board"/regen-board 2>/dev/null || true)
if [ -n "$img" ]; then
  # The capture's ring (`drive::CAP`, its state included) is outside the 16 KiB budget.
  caphex=$(llvm-nm -S -C "$img" | awk '$4 ~ /^regen_board::drive::CAP::/ {print $2}' | head -n1)
  cap=$((16#${caphex:-0}))
  llvm-size -A "$img" | awk -v cap="${cap:-0}" '
    $1 ~ /^\.(vector_table|text|rodata)$/ {flash += $2}
    $1 == ".data" {flash += $2; ram += $2}
    $1 ~ /^\.(bss|uninit)$/ {ram += $2}
    END {printf "board image: flash %d bytes (%.1f KiB, target <= 96 KiB), static RAM %d bytes: the capture ring and its state %d, the rest %d (%.1f KiB, target <= 16 KiB besides the capture buffer)\n", flash, flash/1024, ram, cap, ram - cap, (ram - cap)/1024}'
else
  echo "board image size skipped: no release board image built"
fi
