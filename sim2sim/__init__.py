"""sim2sim: a deployable policy must survive a second simulation, driven by the very runtime of the robot.

`robot-hoi sim2sim --policy P.onnx` runs deploy's unchanged control loop (deploy.loop.Runtime) against a MuJoCo
G1 + Inspire world that differs from training on purpose, under perturbation suites, in parallel processes, and
writes a report folder (metrics.json, summary.md, report.html with plots, videos/*.mp4).

Modules (heavy imports stay inside functions; workers never import torch):
    physics        PhysicsSettings: integrator, solver, step and PD rate of the validation world
    perturbations  Perturbation and the suites (`nominal`, `default`, `robust`)
    scene          the validation model (motor-driven body, gantry, the clip's object) as MJB bytes
    layout         index maps of that model against the policy contract
    world          SimWorld: MuJoCo + the motor drivers' PD loop, latency, gain mismatch, pushes, gantry
    clock          SimClock: the runtime's clock; sleeping steps the world
    sensors        MujocoBody (deploy Body) and MujocoTracker (deploy PoseTracker) with noise and latency
    hands          SimulatedInspireHands: deploy's simulated Inspire devices with MuJoCo fingers
    protocol_simhand  pyserial `simhand://` URLs: the devices' bytes handed over in-process
    monitor        EpisodeMonitor: records, applies InterMimic's early terminations, ends the episode
    metrics        E_h, E_o, success (InterMimic); g-MPJPE, MPJPE, E_acc, E_vel (ComplexMimic); hand stats
    targets        EvalTarget: reference motion + object + scene for one clip
    episode        run_episode(EpisodeJob) -> plain-data result
    runner         run_jobs: one process per core
    summary / tables / plots / video / report   aggregation and the report files
    evaluate       the whole command; cli registers `robot-hoi sim2sim`

Public API:
    from sim2sim.evaluate import Sim2SimOptions, evaluate
    report, paths = evaluate(Sim2SimOptions(policy="policies/untrained.onnx", output="reports/run"))
"""
