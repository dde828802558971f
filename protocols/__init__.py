"""Scripted protocols, as Hydra apps that run unchanged on `hardware=sim|lab|loopback`.

    python -m protocols.force_calibration                    # 100 positions x (5 presses + 4 slides), sim
    python -m protocols.force_calibration positions.count=10 data_root=/data/cal
    python -m protocols.grip_depth grip_depth=9 trajectory=torsion trial=2
    python -m protocols.grip_depth -m grip_depth=6,9,12,15 trajectory=translation,torsion trial='range(7)'
        [hydra/launcher=joblib | hydra/launcher=slurm]

Session files: `<data_root>/force_calibration/<design>/pos042_slide2.mcap`,
`<data_root>/grip_depth/<design>/g12_translation_t3.mcap`, where `<design>` is a short hash of
every setting that shapes the data other than the labels in the file name (`identity`), with a
`design.yaml` manifest: a sweep over any such key writes one folder per value. Rerunning a
stopped command resumes: complete trials of the same identity are skipped, an interrupted one
(left as `<name>.mcap.partial`) is run again, a complete one of another identity is never
replaced. `python -m protocols.sessions DATA_ROOT` lists the designs.

Modules: `calibration` and `grip` (the protocols), `loop` (the one control loop: tick, drain,
faults, deadlines), `runner` (trial files, resume, outcomes, logging), `identity` (trial and
design identity, the design manifest), `stops` (stop reasons and guard trips), `safety` (limits
the framework enforces), `app` (config checks, rig life cycle, exit codes, signals), `progress`
(multirun progress callback), `sessions` (the designs under a data_root), `config` (schemas).
"""
