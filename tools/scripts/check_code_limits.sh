#!/usr/bin/env bash
# Fails, naming each offender, when the library or the tools break one of the code's size limits:
#   - a function of cyclomatic complexity over 20 or longer than 100 lines (lizard -C 20 -L 100),
#     in the library (include/, src/, cuda/), the modules (cli/, sim/, eval/, runner/,
#     benchmark/), the programs (tools/) and examples/; tests (test/, the modules' test/) are not
#     checked (a test is a scenario read top to bottom, and its TEST macros are what lizard sees,
#     not its helpers);
#   - a file-header comment (the `//` lines at the top of a file, after `#pragma once`) of more
#     than 10 lines, in the library and the modules: it says what the file holds, docs/design.md
#     says the rest.
# The functions allowed past the limits are listed, each with its reason, in
# tools/scripts/complexity_exceptions.txt; an entry that no longer exceeds a limit fails too.
# lizard comes from PyPI into a virtual environment under ~/.cache (python3-venv from Debian).
set -euo pipefail
cd "$(dirname "$0")/../.."
readonly max_ccn=20 max_length=100 max_header_lines=10
readonly lizard_version=1.24.3
readonly exceptions=tools/scripts/complexity_exceptions.txt
readonly venv="${XDG_CACHE_HOME:-$HOME/.cache}/covoxslam-lizard-$lizard_version"

if [ ! -x "$venv/bin/lizard" ]; then
  if ! python3 -c 'import venv, ensurepip' 2>/dev/null; then
    sudo=""
    if [ "$(id -u)" != 0 ]; then sudo=sudo; fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends \
      python3 python3-venv
  fi
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/pip" install --quiet --disable-pip-version-check "lizard==$lizard_version"
fi

failed=0

# Functions: lizard's warnings, "file:line: warning: name has N NLOC, C CCN, ...", less the
# listed exceptions.
readonly library=(include src cuda) modules=(cli sim eval runner benchmark)
mapfile -t sources < <(git ls-files -- "${library[@]}" "${modules[@]}" tools examples |
  grep -E '\.(h|hpp|cpp|cu|cuh)$' | grep -v '/test/')
# lizard exits 1 when it warns; anything else, or a line that is not a warning, is its failure.
lizard_status=0
warnings=$("$venv/bin/lizard" -l cpp -C "$max_ccn" -L "$max_length" -w "${sources[@]}") ||
  lizard_status=$?
if [ "$lizard_status" -gt 1 ]; then
  echo "lizard failed (exit status $lizard_status)" >&2
  exit 1
fi
declare -A allowed=()
while read -r file function reason; do
  [[ -z "$file" || "$file" == \#* ]] && continue
  if [ -z "$reason" ]; then
    echo "$exceptions: '$file $function' has no reason" >&2
    failed=1
  fi
  allowed["$file $function"]=1
done < "$exceptions"
declare -A seen=()
while IFS= read -r warning; do
  [ -z "$warning" ] && continue
  if [[ ! "$warning" =~ ^[^\ ]+:[0-9]+:\ warning:\ .+\ has\ [0-9]+\ NLOC ]]; then
    echo "unexpected lizard output: $warning" >&2
    exit 1
  fi
  file=${warning%%:*}
  function=$(sed -E 's/^[^ ]+ warning: (.*) has [0-9]+ NLOC.*/\1/' <<<"$warning")
  seen["$file $function"]=1
  if [ -z "${allowed["$file $function"]+x}" ]; then
    echo "over the limits (CCN $max_ccn, $max_length lines): $warning" >&2
    failed=1
  fi
done <<<"$warnings"
for entry in "${!allowed[@]}"; do
  if [ -z "${seen["$entry"]+x}" ]; then
    echo "$exceptions: '$entry' is within the limits now (or gone): remove its line" >&2
    failed=1
  fi
done

# File-header comments.
while IFS= read -r file; do
  lines=$(awk '
    !started && (/^[[:space:]]*$/ || /^#pragma once/) { next }
    /^[[:space:]]*\/\// { started = 1; count++; next }
    { exit }
    END { print count + 0 }' "$file")
  if [ "$lines" -gt "$max_header_lines" ]; then
    echo "$file: file-header comment of $lines lines (at most $max_header_lines; the rest belongs" \
      "in docs/design.md)" >&2
    failed=1
  fi
done < <(git ls-files -- "${library[@]}" "${modules[@]}" | grep -E '\.(h|hpp|cpp|cu|cuh)$' |
  grep -v '/test/')

if [ "$failed" != 0 ]; then exit 1; fi
echo "code limits: ${#sources[@]} files within CCN $max_ccn, $max_length lines a function" \
  "(${#allowed[@]} listed exceptions) and $max_header_lines-line file headers"
