#!/usr/bin/env bash
# Regenerates examples/office_a/ with mapqual's own pipeline: a 5-minute (simulated) rbpf run of
# the Bormann office_a floorplan, seed 1. The files are what any run's report folder holds, kept
# small so that they can ship with the sources:
#   gt.log / est.log     ground truth and SLAM estimate, CARMEN (FLASER 0 0.0 0.0 0.0 x y theta t)
#   gt.tum / est.tum     the same in TUM format (evo reads it)
#   relations_B.txt      Kümmerle relations (t1 t2 x y z roll pitch yaw), B kind, seed 1
#   map.pgm / map.yaml   the final SLAM map (map_server)
#   summary.json         what `mapqual run` measured, for comparison
# Usage: examples/make_examples.sh   (from the repository root, after `pip install -e .`)
set -euo pipefail
cd "$(dirname "$0")/.."
MAPQUAL=${MAPQUAL:-.venv/bin/mapqual}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
DATABASE_URL="sqlite:///$tmp/examples.db" "$MAPQUAL" run worlds/bormann/office_a.yaml \
    --seed 1 --slam rbpf --time-limit 300 -o "$tmp/run" >/dev/null
mkdir -p examples/office_a
for f in gt.log est.log gt.tum est.tum relations_B.txt map.pgm map.yaml summary.json; do
    cp "$tmp/run/$f" examples/office_a/
done
"$MAPQUAL" evaluate --relations examples/office_a/relations_B.txt --est examples/office_a/est.log
