#!/usr/bin/env bash
# Scores forests on the four validation sets that the docs' comparisons are chosen on
# (docs/training/realism.md, docs/runtime/votes.md): the main job's *training* clips rendered
# with another seed (5005), never the held-out test clips, in four ways:
#   realism-60   the training renders' own settings (what a camera sees), people within +-60
#                degrees of facing the camera;
#   realism-120  the same, people turned up to +-120 degrees;
#   classic-120  whole bodies, mocap arms, no sensor effects (as the test set renders them), +-120;
#   classic-60   the same, +-60.
# and, for the record, on the hand-labelled real Kinect frames. Choose between variations of a
# job on these sets; score the test set and the real frames after the choice.
#
#   scripts/validate.sh [--images N] [--sets a,b] [--no-real] [--rescore] FOREST [FOREST...]
#
# Prints one table row per forest; each set's cell is mAP / visible joints tracked within 0.1 m /
# "not tracked" really hidden / hidden joints placed within 0.15 m (`poseforest eval --method
# meanshift`, mean over joints), the real frames' cell tracked within 0.10 m of 90 (elbows,
# wrists and hands of 54). Needs a build (scripts/build.sh) and the shared data
# (POSEFOREST_DATA_DIR, default ../shared/data). Writes the four job files and every eval's full
# output into $POSEFOREST_OUT/validation (default ./out/validation); an output is reused while the
# forest file, the poseforest binary, the set's job file and the shared data's files (names,
# sizes, times) are the same (--rescore: score again); the pose library is built again when the
# mocap clips change. POSEFOREST_BIN_DIR: the programs (default ./build/bin). About a minute per
# set and forest at 200 frames on two cores.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
# shellcheck source=scripts/default-job.sh
source "$root/scripts/default-job.sh"

usage() { sed -n '13p' "$0" | sed 's/^#   /usage: /' >&2; exit 2; }
die() { echo "validate: $1" >&2; exit "${2:-2}"; }
images=200 sets=realism-60,realism-120,classic-120,classic-60 real=1 rescore=0 forests=()
while (( $# )); do
  case $1 in
    -h|--help) sed -n '2,24p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    --images) (( $# >= 2 )) || usage; images=$2; shift 2 ;;
    --sets) (( $# >= 2 )) || usage; sets=$2; shift 2 ;;
    --no-real) real=0; shift ;;
    --rescore) rescore=1; shift ;;
    -*) die "unknown option '$1' (see --help)" ;;
    *) forests+=("$1"); shift ;;
  esac
done
(( ${#forests[@]} )) || usage
[[ "$images" =~ ^[1-9][0-9]*$ ]] || die "--images must be a positive integer, got '$images'"
IFS=, read -r -a set_list <<< "$sets"
(( ${#set_list[@]} )) || die "--sets is empty"
for s in "${set_list[@]}"; do
  [[ "$s" =~ ^(realism|classic)-(60|120)$ ]] ||
    die "unknown set '$s' in --sets (realism-60, realism-120, classic-120, classic-60)"
done
for f in "${forests[@]}"; do
  [[ -f "$f" && -r "$f" ]] || die "no forest file '$f'" 1
done
data=$(cd "${POSEFOREST_DATA_DIR:-$root/../shared/data}" 2>/dev/null && pwd) ||
  die "no shared data at ${POSEFOREST_DATA_DIR:-$root/../shared/data} (set POSEFOREST_DATA_DIR)" 1
bin=${POSEFOREST_BIN_DIR:-$root/build/bin}
[[ -x "$bin/poseforest" ]] || die "$bin/poseforest not built (run scripts/build.sh)" 1
out=${POSEFOREST_OUT:-$root/out}/validation
mkdir -p "$out/evals"
out=$(cd "$out" && pwd)

# A fingerprint of the files under a folder (names, sizes, modification times; links followed):
# cheap, and it changes when a file is added, removed or rewritten.
fingerprint() { find -L "$@" -type f -printf '%P %s %T@\n' | LC_ALL=C sort | cksum | cut -d' ' -f1; }
data_sum=$(fingerprint "$data")
mocap_sum=$(fingerprint "$data/mocap")

# The pose library the main job trains on (scripts/main-job.sh step 1); its own copy here, so that
# the sets do not move when another script rebuilds out/mocap.pfposes. Built again when the clips
# it came from changed ($poses.clips holds their fingerprint).
poses=$out/mocap.pfposes
if [[ ! -s "$poses" || "$(cat "$poses.clips" 2>/dev/null)" != "$mocap_sum" ]]; then
  echo "validate: pose library from $data/mocap -> $poses" >&2
  "$bin/poseforest-poselib" build --out "$poses.tmp" "$data/mocap" > "$out/poselib.log" 2>&1 ||
    { tail -n 5 "$out/poselib.log" >&2; die "building the pose library failed ($out/poselib.log)" 1; }
  mv "$poses.tmp" "$poses"
  echo "$mocap_sum" > "$poses.clips"
fi
for s in "${set_list[@]}"; do
  style=${s%-*} rotation=${s#*-}
  fields=""
  [[ $style == classic ]] && fields=$classic_test_fields
  write_validation_job "$out/$s.textproto" "$images" "$poses" "$data" "$rotation" "$fields"
done

binary_sum=$(cksum < "$bin/poseforest" | cut -d' ' -f1)
score() {  # FOREST SET_OR_real -> the path of its eval output (scored now unless reusable)
  local forest=$1 set=$2 key file
  # What the eval's output depends on: the forest, the program, the frames (the set's job file,
  # which holds the frame count; the real frames do not depend on it) and the data they are
  # rendered from or read.
  key=$(cksum < "$forest" | cut -d' ' -f1)-$binary_sum-$data_sum
  [[ $set == real ]] || key+=-$(cksum < "$out/$set.textproto" | cut -d' ' -f1)
  file=$out/evals/$(basename "$forest" .pff)-$key-$set.txt
  [[ $set == real ]] && file=$out/evals/$(basename "$forest" .pff)-$key-real.txt
  if (( rescore )) || [[ ! -s "$file" ]]; then
    echo "validate: $forest on $set" >&2
    local args=(--test-set "$out/$set.textproto" --images "$images" --method meanshift)
    [[ $set == real ]] && args=(--real-labels "$data/real/skeltrack_kinect_depth/joint_labels.json")
    if ! "$bin/poseforest" eval --forest "$forest" "${args[@]}" --quiet > "$file.tmp" 2>&1; then
      tail -n 5 "$file.tmp" >&2
      die "poseforest eval failed on $forest, $set (output: $file.tmp)" 1
    fi
    mv "$file.tmp" "$file"
  fi
  REPLY=$file
}
cell() {  # EVAL_OUTPUT -> "mAP / visible / not tracked right / hidden"
  local m s
  m=$(sed -nE 's/^eval: mAP ([0-9.]+) .*/\1/p' "$1")
  local re='^mean over joints: tracked within 0.10 m when visible ([0-9.]+),.* not tracked right ([0-9.]+),'
  re+='.* hidden placed within 0.15 m ([0-9.]+).*'
  s=$(sed -nE "s/$re/\\1 \\/ \\2 \\/ \\3/p" "$1")
  [[ -n "$m" && -n "$s" ]] || die "no mAP or skeleton line in $1" 1
  echo "$m / $s"
}
real_cell() {  # EVAL_OUTPUT -> "N (arms M)"
  local all arms
  all=$(sed -nE 's/^eval: real frames: ([0-9]+) of ([0-9]+) .*/\1 of \2/p' "$1")
  arms=$(sed -nE 's/^elbows, wrists, hands +([0-9]+) +[0-9]+ +([0-9]+) .*/\2 of \1/p' "$1")
  [[ -n "$all" && -n "$arms" ]] || die "no real-frame lines in $1" 1
  echo "$all (arms $arms)"
}

header="| forest |" rule="|---|"
for s in "${set_list[@]}"; do header+=" ${s/-/ +-} |" rule+="---|"; done
(( real )) && header+=" real frames within 0.10 m |" rule+="---:|"
rows=()
for f in "${forests[@]}"; do
  row="| $f |"
  for s in "${set_list[@]}"; do
    score "$f" "$s"
    row+=" $(cell "$REPLY") |"
  done
  if (( real )); then
    score "$f" real
    row+=" $(real_cell "$REPLY") |"
  fi
  rows+=("$row")
done
echo "validation: $images frames per set, the main job's training clips at seed 5005 (never the test clips)"
echo "each set: mAP / visible tracked within 0.1 m / \"not tracked\" really hidden / hidden placed within 0.15 m"
echo "$header"
echo "$rule"
printf '%s\n' "${rows[@]}"
