#!/usr/bin/env bash
# Runs the fuzz targets for SECONDS each (default 600), with seed corpora made on the spot:
#   glb_reader: the GLBs of ../shared/realdata/glb (every exporter and defect there), the demo's
#               asset library, a demo pack and a simulated annotator's edit of it;
#   ingest:     a demo pack and its edit, against that pack (MESA_FUZZ_SCENE);
#   lift_inputs: a demo scene's input/ files, and the forms lift reads that the demo does not
#               write (depth.npy, RLE masks, masks/<id>.png; fuzz/lift_seeds.py);
#   layout_readers: the demo scene's layouts (coarse, refined, settled, truth), their LLM form
#               (`mesa convert --to llm`), its model output, and the published records of
#               ../shared/realdata/layouts/mesatask_gallery (read in place);
#   pickle_reader: sbert_text_features.pkl as Python's pickle writes it with numpy, protocols
#               2-5, float16/float32, numpy 1.x and 2.x names (stages/tests/pickles.py; needs
#               $MESA_PYTHON or python3 with numpy).
# Needs cargo-fuzz (`cargo install cargo-fuzz`) and a nightly toolchain; the corpora grow
# under fuzz/corpus/ (ignored by git), crashes land in fuzz/artifacts/. The fuzz build goes to
# $FUZZ_TARGET_DIR (default: $CARGO_TARGET_DIR/fuzz, else fuzz/target). Built with cargo-fuzz's
# defaults: optimised, debug assertions and overflow checks on, AddressSanitizer.
#
#   fuzz/run.sh [SECONDS] [TARGET...]
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-600}"
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(glb_reader ingest lift_inputs layout_readers pickle_reader)
mesa="${MESA:-${CARGO_TARGET_DIR:-target}/release/mesa}"
fuzz_target_dir="${FUZZ_TARGET_DIR:-${CARGO_TARGET_DIR:-$(pwd)/fuzz/target}/fuzz}"
[ -x "$mesa" ] || cargo build --release
work="fuzz/work"
rm -rf "$work"
"$mesa" demo "$work/demo" --scenes 1 --seed 7 -q
"$mesa" run "$work/demo" --progress off -q || true
scene="$work/demo/scenes/office_table/office_table_0001"
for target in glb_reader ingest; do
  mkdir -p "fuzz/corpus/$target"
  cp "$scene/pack/office_table_0001.glb" "fuzz/corpus/$target/pack.glb"
  cp "$scene/refined/office_table_0001.glb" "fuzz/corpus/$target/refined.glb"
done
cp "$work"/demo/assets/library/*.glb fuzz/corpus/glb_reader/
python3 fuzz/lift_seeds.py "$scene/input" fuzz/corpus/lift_inputs
mkdir -p fuzz/corpus/layout_readers
for rel in coarse/layout.json refined/layout.json qa/layout.json truth/layout.json; do
  [ -f "$scene/$rel" ] && cp "$scene/$rel" "fuzz/corpus/layout_readers/${rel//\//_}"
done
"$mesa" convert "$scene/coarse/layout.json" --to llm -o fuzz/corpus/layout_readers/llm.json
[ -f "$scene/tasks/tasks.jsonl" ] && head -c 65536 "$scene/tasks/tasks.jsonl" > fuzz/corpus/layout_readers/tasks.jsonl
mkdir -p fuzz/corpus/pickle_reader "$work/pickles"
"${MESA_PYTHON:-python3}" stages/tests/pickles.py "$work/pickles"
for f in "$work"/pickles/p[25]_*_C.pkl; do cp "$f" fuzz/corpus/pickle_reader/; done
# The real files are read as a second, read-only corpus (never copied into the repository).
realdata="$(cd "${MESA_SHARED:-../shared}" 2>/dev/null && pwd)/realdata"
shared="$realdata/glb"
export MESA_FUZZ_SCENE="$(pwd)/$scene"
for target in "${targets[@]}"; do
  echo "fuzzing $target for $seconds s"
  extra=()
  [ "$target" = glb_reader ] && [ -d "$shared" ] && extra=("$shared")
  [ "$target" = layout_readers ] && [ -d "$realdata/layouts/mesatask_gallery" ] && extra=("$realdata/layouts/mesatask_gallery")
  # glb_reader explores a GLB's structure: inputs up to 256 KiB keep it fast. ingest needs a
  # whole edited scene (about 430 KiB for the demo's): a shorter limit would cut every seed and
  # leave only the header checks to explore.
  # lift_inputs: the demo's depth.png and photo are about 320 KiB.
  max_len=262144
  [ "$target" = ingest ] && max_len=1048576
  [ "$target" = lift_inputs ] && max_len=524288
  [ "$target" = layout_readers ] && max_len=65536
  # pickle_reader: a 6×768 float32 seed is about 20 KiB.
  [ "$target" = pickle_reader ] && max_len=65536
  (cd fuzz && cargo +nightly fuzz run --target-dir "$fuzz_target_dir" "$target" "corpus/$target" "${extra[@]}" -- \
     -max_total_time="$seconds" -rss_limit_mb=4096 -max_len="$max_len" -print_final_stats=1)
done
