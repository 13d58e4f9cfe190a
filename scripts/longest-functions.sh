#!/usr/bin/env bash
# The N longest functions (default 15) of the library crates' sources
# (shared/src, rig-config/src, host-sim/crates/*/src) and of the commands
# (host-sim/src), longest first, one a line:
#   path:line name length
# A function runs from its `fn` line to the closing brace at the same
# indentation (rustfmt layout), both counted; a one-line body counts 1;
# declarations without a body (trait methods, extern items) are skipped.
# Only prints: it never fails the build.
set -uo pipefail
cd "$(dirname "$0")/.."

n="${1:-15}"
case "$n" in
  '' | *[!0-9]*)
    echo "usage: $0 [N]" >&2
    exit 0
    ;;
esac

files=()
while IFS= read -r f; do files+=("$f"); done < <(find shared/src rig-config/src host-sim/crates/*/src host-sim/src -name '*.rs' 2>/dev/null | sort)
[ "${#files[@]}" -gt 0 ] || exit 0

awk '
  # Net count of "{" minus "}" on a line, ignoring those in // comments,
  # string and char literals (good enough for rustfmt-formatted code).
  function net_braces(s,    t) {
    t = s
    gsub(/\/\/.*$/, "", t)
    gsub(/"([^"\\]|\\.)*"/, "", t)
    gsub(/'\''([^'\''\\]|\\.)'\''/, "", t)
    return gsub(/\{/, "{", t) - gsub(/\}/, "}", t)
  }
  FNR == 1 { depth = 0; pending = 0 }
  {
    line = $0
    # A function whose signature is still open: find its body or its ";".
    if (pending) {
      code = line
      sub(/\/\/.*$/, "", code)
      if (code ~ /\{/) {
        pending = 0
        if (net_braces(code) <= 0) {
          printf "%s:%d %s %d\n", FILENAME, start[depth], name[depth], FNR - start[depth] + 1
          depth--
        }
      } else if (code ~ /;[[:space:]]*$/) {
        pending = 0
        depth--
      }
      next
    }
    # The closing brace of the innermost open function.
    if (depth > 0 && index(line, indent[depth] "}") == 1 && substr(line, length(indent[depth]) + 1) ~ /^\}[[:space:]]*(\/\/.*)?$/) {
      printf "%s:%d %s %d\n", FILENAME, start[depth], name[depth], FNR - start[depth] + 1
      depth--
      next
    }
    if (match(line, /^[[:space:]]*(pub(\([^)]*\))?[[:space:]]+)?((const|async|unsafe|default|extern([[:space:]]+"[^"]*")?)[[:space:]]+)*fn[[:space:]]+[A-Za-z_][A-Za-z0-9_]*/)) {
      head = substr(line, 1, RLENGTH)
      ind = line
      sub(/[^[:space:]].*$/, "", ind)
      fname = head
      sub(/^.*fn[[:space:]]+/, "", fname)
      depth++
      indent[depth] = ind
      name[depth] = fname
      start[depth] = FNR
      code = line
      sub(/\/\/.*$/, "", code)
      if (code ~ /\{/) {
        if (net_braces(code) <= 0) {
          printf "%s:%d %s %d\n", FILENAME, FNR, fname, 1
          depth--
        }
      } else if (code ~ /;[[:space:]]*$/) {
        depth--
      } else {
        pending = 1
      }
    }
  }
' "${files[@]}" | sort -t' ' -k3,3nr -k1,1 | head -n "$n"
exit 0
