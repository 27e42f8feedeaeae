#!/usr/bin/env bash
# Every file of config/ that marks a value as a placeholder is listed in docs/placeholders.md,
# and every file listed there still marks one (docs/placeholders.md).
set -uo pipefail
root="${1:-$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)}"
list="$root/docs/placeholders.md"
status=0
# config/controllers/ holds the Excalibur's line templates, whose fields are "{placeholders}":
# a word of the template language, not a value.
marked="$(cd "$root" && grep -ril 'placeholder' config --exclude-dir=controllers | sort -u)"
for f in $marked; do
  if ! grep -q "^| $f |" "$list"; then
    echo "placeholders: $f marks a placeholder that docs/placeholders.md does not list" >&2
    status=1
  fi
done
for f in $(sed -n 's/^| \(config\/[^ ]*\) |.*/\1/p' "$list" | sort -u); do
  if ! grep -qi 'placeholder' "$root/$f" 2>/dev/null; then
    echo "placeholders: docs/placeholders.md lists $f, which marks no placeholder (derived or" \
         "known now: take it off the list)" >&2
    status=1
  fi
done
[ "$status" -eq 0 ] && echo "placeholders: $(echo "$marked" | wc -w) files, each listed"
exit "$status"
