#!/bin/sh
# Rebuild one sample model: 6 noisy demonstrator runs of 2 laps on TRACK, then behaviour cloning.
#   sh sim/drem_sim/samples/make_sample.sh TRACK NAME [TRAIN_SEED]   (from the repository root, venv active or
#   .venv/bin on PATH; TRAIN_SEED is drem train's --seed, default 0)
set -eu
track="$1"
name="$2"
train_seed="${3:-0}"
work="build/samples/$name"
rm -rf "$work"
for seed in 1 2 3 4 5 6; do
  drem sim record --track "$track" --laps 2 --noise 3 --seed "$seed" --out "$work/runs"
done
drem train --runs "$work/runs" --out "$work/model" --name "$name" --epochs 15 --seed "$train_seed" --threads 1
cp "$work/model/$name.tar.gz" sim/drem_sim/samples/
drem sim eval --model "sim/drem_sim/samples/$name.tar.gz" --track "$track" --laps 5 --out "$work/metrics.json"
