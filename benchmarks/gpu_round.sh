#!/usr/bin/env bash
# The GPU measurements of one session, one part per device call (each under 10 minutes):
#   bash benchmarks/gpu_round.sh fixed|pools|padcost|throughput|answer|profile|floor|frontier|stable|margin|certain|real|plate|linkage|differ|grid|variants|variants_sweep|design|contacts|impratio|agree|plate16|repeat
# The device carries come from tools/device_bundle.sh (three calls stage them).
# Writes JSON/JSONL under $OUT (the device tool brings it back); the tree's commit comes
# in MJX_PICK_COMMIT (the device's copy has no git).
set -euo pipefail
out=${OUT:-benchmarks/out}
mkdir -p "$out"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
# the device's staging installs without bytecode (pip --no-compile), which a user's pip
# install writes: compiled once here, so that imports are timed as a user's (2026-11-28:
# 713 modules compiled from source in a profiled run, 2.9 s)
for site in ${PYTHONPATH//:/ }; do python -m compileall -q -j 0 "$site" >/dev/null 2>&1 || true; done
case "$1" in
  throughput)  # the solver's iteration cap: the old 10 against the new default, same picks
    printf 'iterations = 10\n' > /tmp/it10.toml
    python benchmarks/throughput.py --objects door_opener --solver /tmp/it10.toml \
      --run mujoco:n=4096:batch=1024 --run warp:n=32768:batch=32768 --out "$out/it10" --tag it10
    python benchmarks/throughput.py --objects door_opener \
      --run mujoco:n=4096:batch=1024 --run warp:n=32768:batch=32768 --out "$out/it50" --tag it50
    cp "$out"/it10/*.csv "$out/throughput_it10.csv" 2>/dev/null || true
    cp "$out"/it50/*.csv "$out/throughput_it50.csv" 2>/dev/null || true
    ls -R "$out" ;;
  answer)  # time to answer: a YCB part never seen, then seen (object and compile caches)
    python benchmarks/time_to_answer.py --backend warp --cases "${CASES:-mesh}" \
      --n-mesh 1024 --n-photo 200 --out "$out/time_to_answer_h100.json" ;;
  profile)  # where a second run of a part seen before spends its time (cProfile)
    export MJX_PICK_CACHE_DIR=/tmp/profile_cache
    mesh=mjx_pick/assets/objects/ycb/011_banana.stl
    args=(evaluate "$mesh" --unit m --mass-g 66 --backend warp --n "${N:-1024}" --no-progress)
    python -m mjx_pick.cli "${args[@]}" --out /tmp/profile_a
    python -m mjx_pick.cli "${args[@]}" --out /tmp/profile_b
    python -m cProfile -o "$out/profile.out" -m mjx_pick.cli "${args[@]}" --out /tmp/profile_c
    python -c "import json, sys; [print(f, json.load(open(f'/tmp/profile_{r}/summary.json'))['time_s']) for r in 'abc' for f in [r]]"
    python -c "import pstats; p = pstats.Stats('$out/profile.out'); p.sort_stats('cumulative').print_stats(70); p.sort_stats('tottime').print_stats(30)" > "$out/profile.txt"
    head -c 6000 "$out/profile.txt" ;;
  frontier)  # the time step against labels: Warp at 1 and 2 ms against MuJoCo C at 1 ms
    python benchmarks/throughput.py --objects door_opener \
      --run mujoco:n=4096:batch=1024 --run warp:n=32768:batch=32768 \
      --run warp:n=32768:batch=32768:timestep_s=0.002 --out "$out/frontier" --tag frontier
    cp "$out"/frontier/*.jsonl "$out/frontier.jsonl" 2>/dev/null || true ;;
  stable)  # Warp against C on the labels that a 1 um shift does not flip
    python benchmarks/real_objects.py --n "${N:-512}" --backends mujoco,warp --stability-um 1 \
      --objects "${OBJECTS:-door_opener,040_large_marker,037_scissors,048_hammer,044_flat_screwdriver,011_banana,050_medium_clamp}" \
      --out "$out/real_objects_stable_h100.json" ;;
  margin)  # Warp against C by label margin, 1 um stability and half-step convergence
    python benchmarks/real_objects.py --n "${N:-256}" --backends mujoco,warp --stability-um 1 \
      --gripper "${GRIPPER:-robotiq-2f85}" --force-n "${FORCE:-50}" --margin-bands 0.05,0.1,0.2 --step-check \
      --objects "${OBJECTS:-door_opener,040_large_marker,037_scissors,048_hammer,044_flat_screwdriver,011_banana,050_medium_clamp}" \
      --tables /tmp/margin_tables --out "$out/real_objects_margin_h100.json"
    tar czf "$out/margin_tables.tgz" -C /tmp margin_tables ;;
  certain)  # Warp against C on the labels that 8 placements (0.2 mm, 1 deg) all reproduce
    for o in ${OBJECTS:-door_opener 040_large_marker 037_scissors 048_hammer 044_flat_screwdriver 011_banana 050_medium_clamp}; do
      python benchmarks/real_objects.py --n "${N:-256}" --backends mujoco,warp --stability-um 1 \
        --certain-m 8 --objects "$o" --gripper "${GRIPPER:-robotiq-2f85}" --out "$out/certain_$o.json"
    done ;;
  real)  # six YCB parts, Warp against C on the same pick-points
    python benchmarks/real_objects.py --n "${N:-512}" --backends mujoco,warp \
      --out "$out/real_objects_h100.json" ;;
  variants)  # gripper variants as data on Warp, the tests: Warp's model differs only in
    # carried fields, a sweep of 3 widths compiles once and agrees per scene and with C
    JAX_PLATFORMS=cuda,cpu python -m pytest -o addopts="" -o filterwarnings=ignore -q -s \
      tests/test_variants.py 2>&1 | tee "$out/test_variants_warp.log" || true
    python benchmarks/probes/variant_programs.py --object door_opener > "$out/variant_programs.json" ;;
  design)  # time to answer, design's defaults on the door opener (one compile for all)
    python benchmarks/time_to_answer.py --backend warp --cases design --runs first,second \
      --out "$out/time_to_answer_design_h100.json" ;;
  variants_sweep)  # time to answer, a sweep of 8 finger widths x 512 on Warp (one compile)
    python benchmarks/time_to_answer.py --backend warp --cases sweep --n-sweep 512 \
      --out "$out/time_to_answer_sweep_h100.json" ;;
  floor)  # what any Warp process pays before a pick is simulated: imports and CUDA starts
    t() { local s=$EPOCHREALTIME; "$@" >/dev/null 2>&1; awk -v a="$s" -v b="$EPOCHREALTIME" -v c="${*: -1}" 'BEGIN { printf "%.2f s: %s\n", b - a, c }'; }
    t python -c "pass"
    t python -c "import jax; jax.devices()"
    t python -c "import mjx_pick.cli"
    t python -c "import jax, mujoco; from mujoco import mjx; jax.devices()"
    t python -c "import jax, warp as wp; jax.devices(); wp.init()"
    t python -c "import jax, warp as wp; from mujoco import mjx; from mujoco.mjx.third_party import mujoco_warp; jax.devices(); wp.init()" ;;
  contacts)  # C and Warp collision on the same states (pad contacts per pad, span)
    (cd benchmarks && python probes/contact_sets.py --objects "${OBJECTS:-011_banana,050_medium_clamp,040_large_marker}" \
      --n "${N:-64}" --gripper "${GRIPPER:-robotiq-2f85}" --force-n "${FORCE:-50}" \
      --out "$out/contact_sets_h100${TAG:-}.json") ;;
  fixed)  # issue 55, fixed costs at one GPU: the feasibility checks on one thread beside
    # every core (a million candidates; the search for 262,144 picks), then the door
    # opener's full feasible set as one whole command (its summary's time_s)
    python benchmarks/feasibility.py --object door_opener --n 1000000 --picks 262144 \
      --threads 1,0 --repeats 3 --out "$out"
    t=$EPOCHREALTIME
    CUDA_VISIBLE_DEVICES=${GPUS:-0} python -m mjx_pick.cli evaluate door_opener --n 262144 \
      --seed 0 --backend warp --traces 0 --no-progress --out /tmp/fixed_one | tail -3
    awk -v a="$t" -v b="$EPOCHREALTIME" 'BEGIN { printf "whole command: %.1f s\n", b - a }'
    python -c "import json; s = json.load(open('/tmp/fixed_one/summary.json')); print(json.dumps({k: s.get(k) for k in ('n_feasible', 'picks_per_s', 'time_s', 'device')}))" \
      | tee "$out/fixed_one.json" ;;
  scale)  # issue 55, the door opener's full set as one whole command on 1 / 2 / 4 GPUs of
    # one host (SCALE_GPUS), timed from the shell. A small run on one GPU builds Warp's
    # kernels first (reported apart): after it, no pool size builds anything. Labels of
    # every run against the first's (the same picks: ids must be equal)
    rm -rf /tmp/scale_*
    t=$EPOCHREALTIME
    CUDA_VISIBLE_DEVICES=0 python -m mjx_pick.cli evaluate door_opener --n 4096 --seed 1 \
      --backend warp --traces 0 --no-progress --out /tmp/scale_warm | grep "time, s" || true
    awk -v a="$t" -v b="$EPOCHREALTIME" 'BEGIN { printf "kernels built (4,096 picks): %.1f s\n", b - a }'
    for g in ${SCALE_GPUS:-0 0,1 0,1,2,3}; do
      t=$EPOCHREALTIME
      CUDA_VISIBLE_DEVICES=$g python -m mjx_pick.cli evaluate door_opener --n 262144 --seed 0 \
        --backend warp --traces 0 --no-progress --out "/tmp/scale_$g" | grep "time, s" || true
      w=$(awk -v a="$t" -v b="$EPOCHREALTIME" 'BEGIN { printf "%.1f", b - a }')
      python -c "import json, sys; s = json.load(open('/tmp/scale_$g/summary.json')); print(json.dumps({'gpus': '$g', 'whole_s': float(sys.argv[1]), **{k: s.get(k) for k in ('n_feasible', 'picks_per_s', 'time_s', 'device')}}))" \
        "$w" | tee -a "$out/scale.jsonl"
    done
    python - ${SCALE_GPUS:-0 0,1 0,1,2,3} <<'EOF' | tee "$out/scale_labels.txt"
import sys, pyarrow.parquet as pq
runs = sys.argv[1:]
tab = {g: pq.read_table(f"/tmp/scale_{g}/results.parquet").to_pandas().sort_values("pick_id") for g in runs}
a = tab[runs[0]]
for g in runs[1:]:
    b = tab[g]
    same = (a.pick_id.values == b.pick_id.values).all()
    print(f"{runs[0]} vs {g}: ids equal {same}, labels equal {(a.success.values == b.success.values).mean():.4%}")
EOF
    ;;
  ab)  # issue 55, two trees of the project side by side (TREE_A, TREE_B: folders holding
    # each one's tree), whole commands alternated A, B, A, B...: the YCB banana seen before
    # on one GPU (1,024 picks, REPEATS times each), then the door opener's full set on
    # the GPUs of AB_GPUS (twice each). Kernels and the banana's cache primed first
    banana=(mjx_pick/assets/objects/ycb/011_banana.stl --unit m --mass-g 66)
    whole() {  # tree, label, gpus, evaluate's arguments...
      local tree=$1 label=$2 gpus=$3; shift 3; local t=$EPOCHREALTIME
      (cd "$tree" && CUDA_VISIBLE_DEVICES=$gpus python -m mjx_pick.cli evaluate "$@" \
        --backend warp --traces 0 --no-progress --overwrite --out "/tmp/ab_$label" | grep "time, s")
      awk -v a="$t" -v b="$EPOCHREALTIME" -v l="$label" 'BEGIN { printf "%s: whole command %.2f s\n", l, b - a }'
    }
    whole "$TREE_A" prime_door 0 door_opener --n 4096 --seed 1
    whole "$TREE_B" prime_door_b 0 door_opener --n 4096 --seed 1
    whole "$TREE_A" prime_banana 0 "${banana[@]}" --n 1024
    for r in $(seq "${REPEATS:-3}"); do
      whole "$TREE_A" "A_banana_$r" 0 "${banana[@]}" --n 1024
      whole "$TREE_B" "B_banana_$r" 0 "${banana[@]}" --n 1024
    done
    for r in 1 2; do
      whole "$TREE_A" "A_door_$r" "${AB_GPUS:-0,1,2,3}" door_opener --n 262144 --seed 0
      whole "$TREE_B" "B_door_$r" "${AB_GPUS:-0,1,2,3}" door_opener --n 262144 --seed 0
    done 2>&1 | grep -v "warning: only" ;;
  pools)  # issue 55, a part's first runs on a machine: N_SMALL picks (a small pool: Warp
    # builds its kernels), then N_BIG (a large pool whose tail shrinks: the compaction's
    # gather moves every per-world array; no kernel may be built for it), then N_BIG again
    for n in "${N_SMALL:-1024}" "${N_BIG:-65536}" "${N_BIG:-65536}"; do
      t=$EPOCHREALTIME
      python -m mjx_pick.cli evaluate door_opener --n "$n" --seed 0 --backend warp --traces 0 \
        --no-progress --out "/tmp/pools_${n}_$RANDOM" 2>&1 | grep -E "time, s|compiled\)" | cut -c1-160
      awk -v a="$t" -v b="$EPOCHREALTIME" -v n="$n" 'BEGIN { printf "n %s: whole command %.1f s\n", n, b - a }'
    done | tee "$out/pools.txt" ;;
  padcost)  # issue 55, the pad contact's cost: Warp's step per ContactParams.pad_collision
    # of VARIANTS beside the default (and multiccd off), then each variant's labels on
    # MuJoCo C against the default's on the same picks (1 um stability; label_trust.py)
    variants=(${VARIANTS:-mean_radius pad})
    phys=(--physics default --physics disableflags=524288)
    for v in "${variants[@]}"; do phys+=(--physics "pad_collision=$v"); done
    python benchmarks/warp_profile.py --worlds "${WORLDS:-32768}" --steps 10 "${phys[@]}" \
      --json "$out/warp_profile_padcost.json" | grep -v "^Module"
    mkdir -p /tmp/padcost
    for v in default "${variants[@]}"; do
      c=()
      if [ "$v" != default ]; then
        printf 'pad_collision = "%s"\n' "$v" > "/tmp/padcost/$v.toml"; c=(--contact "/tmp/padcost/$v.toml")
      fi
      python benchmarks/real_objects.py --n "${N:-512}" --backends mujoco --stability-um 1 "${c[@]}" \
        --objects "${OBJECTS:-door_opener,040_large_marker,037_scissors,048_hammer,044_flat_screwdriver,011_banana,050_medium_clamp}" \
        --tables "/tmp/padcost/$v" --out "$out/real_objects_padcost_$v.json" | tail -12
      [ "$v" = default ] || python benchmarks/label_trust.py --a /tmp/padcost/default:mujoco \
        --b "/tmp/padcost/$v:mujoco" --out "$out/padcost_labels_$v.json" | tail -12
    done ;;
  plate)  # the franka-hand's 0.5 kg, 3 mm plate at pad friction 0.3: six copies in one
    # batch under each solver variant (Warp's chatter and drop: solver or time step?)
    mkdir -p /tmp/plate
    printf '' > /tmp/plate/default.toml
    printf 'iterations = 200\n' > /tmp/plate/it200.toml
    printf 'noslip_iterations = 10\n' > /tmp/plate/noslip10.toml
    printf 'impratio = 3.0\n' > /tmp/plate/impratio3.toml
    printf 'timestep_s = 0.0005\n' > /tmp/plate/dt05.toml
    for v in default it200 noslip10 impratio3 dt05; do
      python benchmarks/preset_coulomb.py --backend warp --presets franka-hand --masses 0.5 \
        --heights 3 --frictions 0.3,0.3,0.3,0.3,0.3,0.3 --solver /tmp/plate/$v.toml \
        --out "$out/plate_$v.json"
    done ;;
  plate16)  # that plate, 16 copies in one batch with the step check: as built
    # (plate16.json), then with each option set of VARIANTS ("|"-separated, e.g.
    # "--no-multiccd|--contact box.toml": plate16_variant1.json, ...)
    IFS='|' read -ra variants <<< "|${VARIANTS:-}"
    for k in "${!variants[@]}"; do
      name=plate16; [ "$k" -eq 0 ] || name+="_variant$k"
      # shellcheck disable=SC2086
      python benchmarks/preset_coulomb.py --backend warp --presets franka-hand --masses 0.5 \
        --heights 3 --frictions 0.3 --copies 16 --step-check ${variants[$k]} \
        --out "$out/$name.json"
    done ;;
  linkage)  # the 2F-85 linkage with its rubber-like box pads on Warp: the preset grid, and
    # Warp against C on the door opener and YCB parts (the same pick-points)
    python benchmarks/preset_coulomb.py --backend warp --presets robotiq-2f85-linkage \
      --out "$out/preset_coulomb_warp_linkage.json"
    python benchmarks/real_objects.py --n "${N:-256}" --backends mujoco,warp --stability-um 1 \
      --gripper robotiq-2f85-linkage --out "$out/real_objects_linkage_h100.json" \
      --objects "${OBJECTS:-door_opener,040_large_marker,037_scissors,048_hammer,044_flat_screwdriver,011_banana,050_medium_clamp}" ;;
  differ)  # the picks certain on C that Warp labelled otherwise, 8 copies each on both
    (cd benchmarks
     python probes/differing_picks.py --object 048_hammer --pick-ids 6108 --out "$out/differ_hammer.json"
     python probes/differing_picks.py --object 050_medium_clamp --pick-ids 1084 --out "$out/differ_clamp.json"
     python probes/differing_picks.py --object 011_banana --pick-ids 1472 --out "$out/differ_banana.json") ;;
  grid)  # the preset Coulomb grid on Warp; STEP_CHECK=1 COPIES=3 PRESETS=... for the
    # step check's flags on Warp's run-to-run spread (one JSON per call: PRESETS splits it)
    python benchmarks/preset_coulomb.py --backend warp --presets "${PRESETS:-robotiq-2f85,robotiq-2f85-linkage,robotiq-2f140,onrobot-rg2,franka-hand}" \
      --copies "${COPIES:-1}" ${STEP_CHECK:+--step-check} ${SOLVER:+--solver "$SOLVER"} \
      --out "$out/preset_coulomb_warp${TAG:-}.json" ;;
  impratio)  # Warp against C at each impratio of IMPRATIOS, the same pick-points, labels
    # and 1 um stability (soft friction's creep, which impratio divides, against labels)
    for v in ${IMPRATIOS:-30 100}; do
      printf 'impratio = %s\n' "$v" > "/tmp/impratio$v.toml"
      python benchmarks/real_objects.py --n "${N:-256}" --backends mujoco,warp --stability-um 1 \
        --gripper "${GRIPPER:-robotiq-2f85}" --force-n "${FORCE:-50}" --solver "/tmp/impratio$v.toml" \
        --objects "${OBJECTS:-door_opener,040_large_marker,037_scissors,048_hammer,044_flat_screwdriver,011_banana,050_medium_clamp}" \
        --out "$out/real_objects_impratio${v}_${GRIPPER:-robotiq-2f85}_h100.json"
    done ;;
  agree)  # Warp against C at the default physics, labels and 1 um stability, for each
    # GRIPPER:FORCE of GRIPPERS (e.g. "robotiq-2f140:50 onrobot-rg2:30"), N picks a part;
    # FLAGS: more real_objects.py options (e.g. --no-multiccd), TAG: the files' suffix
    for gf in ${GRIPPERS:-robotiq-2f85:50}; do
      # shellcheck disable=SC2086
      python benchmarks/real_objects.py --n "${N:-256}" --backends mujoco,warp --stability-um 1 ${FLAGS:-} \
        --gripper "${gf%%:*}" --force-n "${gf##*:}" \
        --objects "${OBJECTS:-door_opener,040_large_marker,037_scissors,048_hammer,044_flat_screwdriver,011_banana,050_medium_clamp}" \
        --out "$out/real_objects_agree_${gf%%:*}_n${N:-256}${TAG:-}.json"
    done ;;
  repeat)  # Warp's run-to-run against Warp = C: for each GRIPPER:FORCE of GRIPPERS, run A
    # (C and Warp) and run B (Warp again, a new process) on the same N picks of OBJECTS,
    # then Warp A = C, Warp B = C and Warp A = Warp B, each on the labels stable on C
    # (label_trust.py --flags: C's stability copies are the only ones the figures read,
    # so run B has none); tables and figures in repeat.tgz
    mkdir -p /tmp/repeat
    for gf in ${GRIPPERS:-robotiq-2f85:50}; do
      g=${gf%%:*}; f=${gf##*:}
      for run in A B; do
        opts=(--backends mujoco,warp --stability-um 1); [ "$run" = A ] || opts=(--backends warp)
        python benchmarks/real_objects.py --n "${N:-1024}" "${opts[@]}" \
          --gripper "$g" --force-n "$f" --objects "${OBJECTS:-048_hammer}" \
          --tables "/tmp/repeat/${g}_$run" --out "/tmp/repeat/real_objects_${g}_$run.json"
      done
      t=/tmp/repeat/$g
      python benchmarks/label_trust.py --a "${t}_A:mujoco" --b "${t}_A:warp" --out "${t}_c_warpA.json"
      python benchmarks/label_trust.py --a "${t}_A:mujoco" --b "${t}_B:warp" --out "${t}_c_warpB.json"
      python benchmarks/label_trust.py --a "${t}_A:warp" --b "${t}_B:warp" --flags "${t}_A:mujoco" \
        --out "${t}_warpA_warpB.json"
    done
    tar czf "$out/repeat.tgz" -C /tmp repeat ;;
esac
