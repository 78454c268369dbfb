#!/usr/bin/env bash
# On a GPU machine (no container runtime needed): the catgs-server binary that docker/Dockerfile.cuda
# built, with its image's libraries, as exported by `tests/container/cuda_image_build.sh --export
# DIR` (DIR/image.tar.xz: catgs-server, the page, the libraries beyond the C library, and a
# catgs-loadgen built in the image's build stage). Checks, output under $OUT (default ./out):
#   - the architectures the binary carries (cuobjdump, SASS and PTX) and no library missing;
#   - the server on the bundled biker scene with `--renderer cuda --encoder auto`: /readyz time;
#     2 sessions at 1280x720 whose every 10th frame is decoded and compared with the CPU render of
#     its pose (catgs-loadgen --check-every, PSNR bar 30 dB); 8 sessions at 1920x1080, 60 poses/s;
#   - SIGTERM during a session (--drain-timeout-s 5): exit code and time, what the session got;
#   - with no GPU visible, `--renderer cuda` exits non-zero with its reason.
# Exit status 1 when a check fails: a library missing, the server not ready within 60 s, a session
# of the two loadgen runs failing (a reference check below the bar among them), the server's exit
# code after SIGTERM other than 0 or the session in the drain not told ERROR_SHUTTING_DOWN (it
# then exits 1: that session's failure is the expected end), or an exit code 0 without a GPU.
# The binaries need the glibc of the image (Ubuntu 24.04: 2.39); on Debian 12 (2.36) they do not start.
# usage (repository root): tests/container/cuda_image_gpu_run.sh [TARBALL]   (default .carry_img/image.tar.xz)
set -u
cd "$(dirname "$0")/../.."
status=0
failed() { echo "FAIL: $*" | tee -a "$OUT/image_run.txt"; status=1; }
R=$PWD
OUT=${OUT:-$R/out}
mkdir -p "$OUT"
TARBALL=${1:-.carry_img/image.tar.xz}
D=$(mktemp -d)
tar -C "$D" -xJf "$TARBALL"
export LD_LIBRARY_PATH=$D/lib
{
  echo "== machine"; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; nproc
  echo "== cuobjdump --list-elf / --list-ptx"
  /usr/local/cuda/bin/cuobjdump --list-elf $D/catgs-server | grep -o 'sm_[0-9]*' | sort | uniq -c
  /usr/local/cuda/bin/cuobjdump --list-ptx $D/catgs-server | grep -o 'sm_[0-9]*' | sort | uniq -c
  echo "== ldd not found"; ldd $D/catgs-server $D/catgs-loadgen | grep "not found" || echo none
} > $OUT/image_run.txt 2>&1
grep -q "=> not found" $OUT/image_run.txt && failed "libraries missing"
cat $OUT/image_run.txt
SCENE=$R/assets/scenes/biker.compressed.ply
$D/catgs-server --scene $SCENE --renderer cuda --encoder auto --port 8080 --bind 127.0.0.1 \
  --web-root $D/web_client --drain-timeout-s 5 > $OUT/server.log 2>&1 &
SRV=$!
t0=$(date +%s%N)
ready=0
for i in $(seq 1 120); do
  $D/catgs-server --probe http://127.0.0.1:8080/readyz >/dev/null 2>&1 && { ready=1; break; }
  sleep 0.5
done
[ $ready = 1 ] || failed "not ready within 60 s"
echo "== ready after $(( ($(date +%s%N) - t0) / 1000000 )) ms" | tee -a $OUT/image_run.txt
head -20 $OUT/server.log
echo "== loadgen: 2 sessions 1280x720, every 10th frame checked against the CPU render"
$D/catgs-loadgen --port 8080 --scene $SCENE --sessions 2 --size 1280x720 --seconds 10 --decode 1 \
  --check-every 10 --json $OUT/loadgen_check.json --progress 0 > $OUT/loadgen_check.txt 2>&1
rc=$?; [ $rc = 0 ] || failed "the checked sessions (catgs-loadgen exit $rc)"
echo "rc $rc" >> $OUT/loadgen_check.txt; tail -25 $OUT/loadgen_check.txt
echo "== loadgen: 8 sessions 1920x1080 at 60 Hz"
$D/catgs-loadgen --port 8080 --scene $SCENE --sessions 8 --size 1920x1080 --seconds 15 --rate 60 \
  --json $OUT/loadgen_1080p8.json --progress 0 > $OUT/loadgen_1080p8.txt 2>&1
rc=$?; [ $rc = 0 ] || failed "the 1080p sessions (catgs-loadgen exit $rc)"
echo "rc $rc" >> $OUT/loadgen_1080p8.txt; tail -25 $OUT/loadgen_1080p8.txt
curl -s http://127.0.0.1:8080/metrics > $OUT/metrics.txt 2>/dev/null || true
echo "== SIGTERM during a session"
$D/catgs-loadgen --port 8080 --scene $SCENE --sessions 1 --size 640x480 --seconds 20 --progress 0 \
  > $OUT/loadgen_drain.txt 2>&1 &
LG=$!
sleep 3
t1=$(date +%s%N)
kill -TERM $SRV; wait $SRV; rc=$?
[ $rc = 0 ] || failed "server exit $rc after SIGTERM"
echo "server exit $rc after $(( ($(date +%s%N) - t1) / 1000000 )) ms" | tee -a $OUT/image_run.txt
wait $LG; echo "loadgen rc $?" >> $OUT/loadgen_drain.txt
grep -q "ERROR_SHUTTING_DOWN" $OUT/loadgen_drain.txt || failed "the session was not told ERROR_SHUTTING_DOWN"; tail -8 $OUT/loadgen_drain.txt
tail -15 $OUT/server.log
echo "== no GPU visible: --renderer cuda must exit non-zero"
CUDA_VISIBLE_DEVICES="" timeout 60 $D/catgs-server --scene $SCENE --renderer cuda --port 8081 > $OUT/nogpu.log 2>&1
rc=$?; { [ $rc != 0 ] && [ $rc != 124 ]; } || failed "without a GPU: exit $rc"
grep -q "cuda renderer unavailable" $OUT/nogpu.log || failed "without a GPU: no 'cuda renderer unavailable'"
echo "exit $rc" >> $OUT/nogpu.log; tail -3 $OUT/nogpu.log
exit $status
