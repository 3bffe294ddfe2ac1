#!/usr/bin/env bash
# Every Python the package claims: build the wheel once (abi3, cp39 and later), install it
# with a plain `pip install` (no optional dependencies) into fresh virtual environments of
# the oldest and the newest Python found (pyenv's, else python3.X on PATH), and run the
# README's Python steps there (scripts/readme_smoke.py).
#   bash scripts/check_pythons.sh            # oldest + newest
#   PYTHONS="3.9 3.12" bash scripts/check_pythons.sh
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}

want=${PYTHONS:-}
found=()
for v in 3.9 3.10 3.11 3.12 3.13 3.14; do
  exe=""
  if command -v pyenv >/dev/null 2>&1; then
    d=$(pyenv root)/versions
    m=$(ls -d "$d"/"$v".* 2>/dev/null | sort -V | tail -1 || true)
    [ -n "$m" ] && [ -x "$m/bin/python" ] && exe="$m/bin/python"
  fi
  [ -z "$exe" ] && command -v "python$v" >/dev/null 2>&1 && exe=$(command -v "python$v")
  [ -n "$exe" ] && found+=("$v=$exe")
done
if [ ${#found[@]} -eq 0 ]; then echo "check_pythons: no Python 3.9+ found" >&2; exit 1; fi
if [ -z "$want" ]; then
  first=${found[0]%%=*}; last=${found[${#found[@]}-1]%%=*}
  want="$first $last"
fi
echo "check_pythons: found ${found[*]%%=*}; testing $want"

rm -rf target/wheels
"$PY" -m maturin build --release -o target/wheels >/dev/null
wheel=$(ls target/wheels/popup-*.whl | head -1)
echo "check_pythons: wheel $wheel"
for v in $want; do
  exe=""
  for f in "${found[@]}"; do [ "${f%%=*}" = "$v" ] && exe=${f#*=}; done
  [ -z "$exe" ] && { echo "check_pythons: Python $v not found" >&2; exit 1; }
  venv=target/venvs/py$v
  rm -rf "$venv"
  "$exe" -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "$wheel"
  echo "check_pythons: Python $v"
  # run from outside the source tree, so that the installed package (not python/) is imported
  (cd target && MPLBACKEND=Agg "../$venv/bin/python" ../scripts/readme_smoke.py)
done
echo "check_pythons: ok ($want)"
