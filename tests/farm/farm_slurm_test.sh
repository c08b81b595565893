#!/usr/bin/env bash
# The farm on a real Slurm cluster (ctest label `farm`): a shot is re-timed 24 -> 30 fps as a
# 4-task job array (2 frames x 2 crop tiles) plus the dependent final step, and every output
# must equal a local render byte for byte. On the way, the failure path: the job is submitted
# held, and tile 1's output directory replaced by a file before it is released, so the two
# tasks of tile 1 fail;
# `farm status` must name them with their logs and the final step must not run; then, the store
# restored, the same command resubmits only the failed tasks and the job completes.
#   tests/farm/farm_slurm_test.sh RESHUTTER WORKDIR
set -euo pipefail
bin=$(realpath "$1")
work=$2
here=$(cd "$(dirname "$0")" && pwd)
rm -rf "$work" && mkdir -p "$work/shot" "$work/out"
cd "$work"

# A three-frame shot: a translucent ball crossing a floor.
{
  echo 'Format 160 90 1'; echo 'Shutter 0 1'; echo 'Projection "perspective" "fov" [40]'
  for f in 1 2 3; do
    a=$(awk "BEGIN{print -1.5 + 0.5*$f}"); b=$(awk "BEGIN{print -1.0 + 0.5*$f}")
    cat <<RIB
FrameBegin $f
WorldBegin
LightSource "distantlight" 1 "intensity" [1]
Surface "plastic"
AttributeBegin Translate 0 -1 6 Rotate -70 1 0 0 Color [0.3 0.6 0.3] Polygon "P" [-4 -4 0 4 -4 0 4 4 0 -4 4 0] AttributeEnd
AttributeBegin Opacity [0.5 0.5 0.5] MotionBegin [0 1] Translate $a 0 5 Translate $b 0 5 MotionEnd Color [1 0.2 0.1] Sphere 0.7 -0.7 0.7 360 AttributeEnd
WorldEnd
FrameEnd
RIB
  done
} > shot/shot.rib
"$bin" -q shade shot/shot.rib -o shot/shot.####.mps

submit=("$bin" farm retime shot/shot.####.mps --to-fps 30 --frames 2-3 -o out/ntsc.####.exr --deep out/deep.####.exr
        --chunk 1 --tiles 2x1 --job-dir out/ntsc.farm)

farm_run() {
  set -euo pipefail
  # 1. Held, then tile 1's flat output directory made a file.
  "${submit[@]}" --sbatch=--hold
  [ "$(squeue --noheader -o %i | wc -l)" -ge 2 ] || { echo "FAIL: the job is not queued"; exit 1; }
  rmdir out/ntsc.farm/tiles/1/flat && touch out/ntsc.farm/tiles/1/flat
  for j in $(squeue --noheader -o %A); do scontrol release "$j"; done
  for _ in $(seq 300); do [ -z "$(squeue --noheader -o %i)" ] && break; sleep 0.2; done
  [ -z "$(squeue --noheader -o %i)" ] || { echo "FAIL: jobs still queued: $(squeue)"; exit 1; }
  set +e; "$bin" farm status out/ntsc.farm > status1.txt; rc=$?; set -e
  cat status1.txt
  [ $rc -eq 1 ] || { echo "FAIL: farm status should exit 1 with failed tasks, got $rc"; exit 1; }
  grep -q "2 done, 2 failed" status1.txt || { echo "FAIL: expected 2 done and 2 failed tasks"; exit 1; }
  grep -q "FAILED  task 1: frames 2, tile 1" status1.txt && grep -q "FAILED  task 3: frames 3, tile 1" status1.txt \
    || { echo "FAIL: the failed tasks are not named"; exit 1; }
  grep -q "tiles/1/flat" status1.txt || { echo "FAIL: the failed tasks' log lines do not name the broken directory"; exit 1; }
  [ ! -e out/ntsc.farm/status/assemble.exit ] || { echo "FAIL: the final step ran although tasks failed (afterok)"; exit 1; }
  [ ! -e out/ntsc.0002.exr ] || { echo "FAIL: frame 2 was assembled although the final step must not have run"; exit 1; }
  # 2. Restored; the same command resumes: only tasks 1 and 3 run again.
  rm out/ntsc.farm/tiles/1/flat
  "${submit[@]}" --wait > submit2.txt 2>&1 || { cat submit2.txt; echo "FAIL: the resubmitted job failed"; exit 1; }
  cat submit2.txt
  grep -q "submitted 2 of 4 tasks" submit2.txt || { echo "FAIL: the resubmission should run only the 2 failed tasks"; exit 1; }
  grep -q "^#SBATCH --array=1,3$" out/ntsc.farm/tasks.sh || { echo "FAIL: tasks.sh should hold --array=1,3"; exit 1; }
  grep -q "4 done, 0 failed" submit2.txt || { echo "FAIL: expected every task done"; exit 1; }
  [ "$(cat out/ntsc.farm/status/assemble.exit)" = 0 ] || { echo "FAIL: the final step did not succeed"; exit 1; }
  for i in 0 1 2 3; do
    [ "$(cat out/ntsc.farm/status/task.$i.exit)" = 0 ] || { echo "FAIL: task $i has no success status"; exit 1; }
    grep -q "task $i:" out/ntsc.farm/logs/task.$i.log || { echo "FAIL: task $i's log is not the task's"; exit 1; }
  done
}
export -f farm_run
export bin
export submit_str="${submit[*]}"
# Arrays do not cross `bash -c`: rebuild it there.
"$here/slurm_cluster.sh" "$work/cluster" bash -c 'submit=($submit_str); farm_run'

# 3. Every output equals a local render of the same frames, byte for byte.
"$bin" -q retime shot/shot.####.mps --to-fps 30 --frames 2-3 -o local.####.exr --deep localdeep.####.exr
for f in 0002 0003; do
  cmp out/ntsc.$f.exr local.$f.exr
  cmp out/deep.$f.exr localdeep.$f.exr
done
[ -z "$(find out/ntsc.farm/tiles -type f)" ] || { echo "FAIL: tiles left after assembly"; exit 1; }
echo "PASS: 4-task array on Slurm, failure reported and resumed, outputs byte-identical to the local render"
