#!/usr/bin/env bash
# Wall time of each command README.md gives, as a newcomer meets them: run in order in a fresh
# clone with an empty JAX compilation cache (cold), then all again (warm: cache and STM files
# in place).  Prints a Markdown table; README.md's timings come from it (2-core machine).
#
#   bash scripts/time_commands.sh [CACHE_DIR]      # from the repository root, after `make venv`
#
# The cache folder (default: a new temporary one) is emptied first; nothing outside out/,
# stm_files/ and that folder is written.
set -uo pipefail
cd "$(dirname "$0")/.."
CACHE=${1:-$(mktemp -d)}
rm -rf "$CACHE" && mkdir -p "$CACHE" out stm_files
export FRACAS_CACHE_DIR="$CACHE"
F=.venv/bin/fracas
COMMANDS=(
  "$F run namelists/earth_mars_guidance.toml"
  "$F propagate namelists/leo_j2.toml -o out/leo_j2.h5 --plot out/leo_j2.png"
  "$F propagate namelists/earth_mars_sep.toml -o out/earth_mars_sep.h5 --plot out/earth_mars_sep.png"
  "$F propagate namelists/near_earth_spiral.toml -o out/near_earth_spiral.h5 --plot out/near_earth_spiral.png"
  "$F run namelists/earth_mars_team.toml -o out/earth_mars_team.h5 --plot out/earth_mars_team.png"
  "$F stm build namelists/mercury_approach_team.toml -o stm_files/mercury_approach.h5"
  "$F stm info stm_files/mercury_approach.h5"
  "$F run namelists/mercury_approach_team.toml --stm stm_files/mercury_approach.h5"
  "$F run namelists/mercury_approach_guidance.toml --quiet"
  "$F report out/earth_mars_team.h5 --quiet"
  "$F sweep namelists/earth_mars_sweep.toml --workers 0"
  "$F run namelists/near_earth_spiral_tom.toml -o out/near_earth_spiral_tom.h5"
  "$F run namelists/near_earth_spiral_team.toml --trajectory-deck out/near_earth_spiral_tom_reference.toml --quiet"
  "$F run namelists/earth_mars_tsim.toml"
  "$F run namelists/apollo12_rendezvous.toml"
  "$F import-namelist namelists/legacy/earth_mars_team.nml -o out/imported_earth_mars_team.toml --force"
  "$F validate out/imported_earth_mars_team.toml"
  "$F export out/earth_mars_team.h5 --oem out/earth_mars_team.oem"
  "$F run namelists/lambert_tom.toml"
  "$F validate namelists/*.toml"
)
declare -A COLD
for pass in cold warm; do
  for c in "${COMMANDS[@]}"; do
    t0=$(date +%s.%N)
    bash -c "$c" > /dev/null 2>&1
    rc=$?
    t=$(echo "$(date +%s.%N) - $t0" | bc)
    if [ "$pass" = cold ]; then
      COLD["$c"]="$t $rc"
    else
      read -r tc rcc <<< "${COLD[$c]}"
      if [ "$rcc" != 0 ] || [ "$rc" != 0 ]; then  # no time for a failed run (a propagation short of its end exits non-zero)
        printf '| `%s` | FAILED (exit %s) | FAILED (exit %s) | %s |\n' "${c#"$F "}" "$rcc" "$rc" "$rcc/$rc"
      else
        printf '| `%s` | %.0f | %.1f | %s |\n' "${c#"$F "}" "$tc" "$t" "$rcc/$rc"
      fi
    fi
  done
done | { echo "| command | cold (s) | warm (s) | exit cold/warm |"; echo "|---|---|---|---|"; cat; }
