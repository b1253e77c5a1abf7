#!/bin/bash
# One lease of a lent GPU machine (torch there, no pybullet, no package registry, a 64 MiB working tree):
# continue the narrow detector line (YOLOv8n at width 0.125 with ReLU, pruned from the v7 line) there.
#
# Here, before the lease (docs/detector.md, "A narrower network"):
#   python scripts/pack_dataset_jpeg.py datasets/sim datasets/sim2-families datasets/sim4-egl --out /tmp/pack --width 224 --quality 75
#   mkdir -p .gpu && tar czf .gpu/data.tar.gz -C /tmp/pack sim sim2-families sim4-egl     # ~50 MB
#   printf '/.gpu/\n/.whl/\n' >> .git/info/exclude
#   python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
#       --platform manylinux2014_x86_64 -d .whl ultralytics-opencv-headless==8.4.190 ultralytics-thop==2.2.3 \
#       onnxslim==0.1.98 ultralytics-platform==0.1.99
#   # the tracked models are ~50 MB: move the ones the run does not read out of the tree for the call
#   # (git checkout assets/models afterwards), keeping the line's checkpoint
# The call: run(command="bash scripts/gpu_train_narrow.sh", carry=[".gpu", ".whl"], timeout_s=600);
# the checkpoint, the float model, its card and the log come back in $OUT.
set -o pipefail
t0=$(date +%s)
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 3
export PYTHONPATH=/tmp/site PYTHONUNBUFFERED=1
mkdir -p /tmp/data && tar xzf .gpu/data.tar.gz -C /tmp/data || exit 4
nvidia-smi -L; echo "$(nproc) cores; setup $(( $(date +%s) - t0 )) s"
CKPT=${CKPT:-assets/models/detector-n8r-train.pt}
timeout ${LIMIT:-520} python3 scripts/train_detector_nopolars.py --resume --checkpoint "$CKPT" \
  --data /tmp/data/sim --data /tmp/data/sim2-families --data /tmp/data/sim4-egl \
  --device 0 --batch 64 --workers 14 --epochs ${EPOCHS:-200} --hours ${HOURS:-0.115} --fit-schedule \
  --no-int8 --out "$OUT/detector-float.onnx" --runs /tmp/runs 2>&1 | grep -v "━" | tee "$OUT/train.log"
echo "rc $? total $(( $(date +%s) - t0 )) s"
cp "$CKPT" "$OUT/" 2>/dev/null
ls -la "$OUT"
