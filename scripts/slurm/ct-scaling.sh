#!/bin/bash
# Strong scaling of the paper-size CT at 4.3 m/s (155,600 points, 1 mm cells): the same 20 steps on
# P = 1, 2, 4, ..., 512 processes, one core and one thread each, one output directory per P, and the
# per-step timings of every run's history.csv collected into one CSV for the scaling model
# (docs/scaling.md; `python3 tools/scaling_model/model.py --measured runs/scaling/scaling.csv`).
#
#   sbatch scripts/slurm/ct-scaling.sh                         # from the repository root, after
#                                                              # cargo build --release
#   PS="1 2 4 8" sbatch --nodes=1 scripts/slurm/ct-scaling.sh  # a shorter series
#   CONFIG=configs/ct-paper-4.3mps.toml sbatch scripts/slurm/ct-scaling.sh   # the converged choice
#   EXTRA="--set extrusion.thickness=50 --allow-large" ...     # the CT as a 50 mm plate (3D; large)
#
# Variables (environment): CONFIG (default configs/ct-paper-c1-4.3mps.toml, the configuration of the
# measurements in docs/benchmarks.md), STEPS (20), PS (the process counts), OUT (runs/scaling), EXTRA
# (more program arguments, before the PETSc options), PETSC (PETSc options; default
# "-mat_type aij -snes_lag_preconditioner 1", the solver of the measurements the model is calibrated on:
# point storage on every P (one process would otherwise store the Jacobian by node blocks, whose ILU
# kernels are 1.4-1.8x faster, and the series would compare two storages) and a factorisation at every
# Newton iteration; PETSC="" runs the run command's defaults), BIN.
#
# The bands of the partition are cut across the grid's cell rows and need at least one row each: the
# paper-size grid has 216 (200 cells and 2 x 8 of margin), so P = 256 and 512 are refused by the program
# today (docs/scaling.md, "Bands"); they are skipped below and reported in the CSV's log.
#
#SBATCH --job-name=ct-scaling
#SBATCH --nodes=16
#SBATCH --ntasks-per-node=32
#SBATCH --cpus-per-task=1
#SBATCH --time=02:00:00
#SBATCH --exclusive
#SBATCH --output=ct-scaling-%j.out

set -euo pipefail

BIN=${BIN:-target/release/mpm-concrete}
CONFIG=${CONFIG:-configs/ct-paper-c1-4.3mps.toml}
STEPS=${STEPS:-20}
PS=${PS:-"1 2 4 8 16 32 64 128 256 512"}
OUT=${OUT:-runs/scaling}
EXTRA=${EXTRA:-}
PETSC=${PETSC--mat_type aij -snes_lag_preconditioner 1}
MAX_ROWS=${MAX_ROWS:-216}   # cell rows of the grid: bands need P <= rows

# One thread per process: the point loops would otherwise use the cores Slurm gives each task.
export RAYON_NUM_THREADS=1
export OMP_NUM_THREADS=1

[ -x "$BIN" ] || { echo "no $BIN: run cargo build --release first" >&2; exit 1; }
mkdir -p "$OUT"
echo "job ${SLURM_JOB_ID:-local} on ${SLURM_JOB_NUM_NODES:-1} nodes: $CONFIG, $STEPS steps, P = $PS" | tee "$OUT/series.log"

TASKS=${SLURM_NTASKS:-1}
for P in $PS; do
    if [ "$P" -gt "$MAX_ROWS" ]; then
        echo "P=$P: skipped (more processes than the grid's $MAX_ROWS cell rows)" | tee -a "$OUT/series.log"
        continue
    fi
    if [ "$P" -gt "$TASKS" ]; then
        echo "P=$P: skipped (the allocation has $TASKS tasks)" | tee -a "$OUT/series.log"
        continue
    fi
    dir="$OUT/p$(printf %03d "$P")"
    start=$(date +%s.%N)
    # shellcheck disable=SC2086 # EXTRA and PETSC are word lists
    if srun --ntasks="$P" --cpus-per-task=1 --cpu-bind=cores --exact \
        "$BIN" run "$CONFIG" --steps "$STEPS" --output "$dir" --overwrite --quiet $EXTRA $PETSC \
        >"$dir.log" 2>&1; then
        status=ok
    else
        status="failed (exit $?, see $dir.log)"
    fi
    end=$(date +%s.%N)
    echo "P=$P: $status, whole command $(awk -v a="$start" -v b="$end" 'BEGIN { printf "%.1f", b - a }') s" | tee -a "$OUT/series.log"
done

# The per-step timings of every run, one CSV: processes, then the history's step, Newton and Krylov
# iterations, unknowns, wall times of the phases and the bytes of the largest process (several processes).
awk -F, -v OFS=, '
    FNR == 1 {
        delete col
        for (i = 1; i <= NF; i++) col[$i] = i
        match(FILENAME, /p[0-9]+\//); p = substr(FILENAME, RSTART + 1, RLENGTH - 2) + 0
        if (!header++) print "processes,step,newton_its,linear_its,unknowns,wall_setup,wall_assembly,wall_solve,wall_total,bytes_sent,bytes_unknowns"
        next
    }
    { b = ("bytes_sent" in col) ? $col["bytes_sent"] : 0; u = ("bytes_unknowns" in col) ? $col["bytes_unknowns"] : 0
      print p, $col["step"], $col["newton_its"], $col["linear_its"], $col["unknowns"], $col["wall_setup"], $col["wall_assembly"], $col["wall_solve"], $col["wall_total"], b, u }
' "$OUT"/p*/history.csv > "$OUT/scaling.csv"
echo "collected $(($(wc -l < "$OUT/scaling.csv") - 1)) steps into $OUT/scaling.csv" | tee -a "$OUT/series.log"
echo "compare: python3 tools/scaling_model/model.py --measured $OUT/scaling.csv" | tee -a "$OUT/series.log"
