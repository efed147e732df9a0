"""Teachers as Ray tasks: `robot-hoi train --cluster ray [--address ADDR]`.

One Ray task per teacher group runs robot_hoi.rl.teacher_job.train_teacher_group (the code path of the
sequential loop) with its own CPUs and GPU (--cpus-per-teacher, --gpus-per-teacher; by default one GPU per
teacher when the cluster has GPUs, and a teacher holding a GPU trains on it). Ray re-runs a task whose worker
died (pre-emption, a lost node) or raised, up to --max-retries times; the re-run resumes from the group's latest
checkpoint with the budget that is left (teacher_job's job_state.json). Bad input (a UserError) is reported once,
not retried. The driver prints a line per teacher as it finishes and a table at the end.

Where results land. Before submitting, the driver writes a fresh random token (one per invocation) into
RUN/.ray_run_token. A worker that reads the same token there sees the driver's filesystem (the local Ray instance,
or cluster nodes that mount the run folder, e.g. NFS, as Ray Train's storage_path expects): it trains straight
into RUN/<group>/. A worker that does not (another machine with its own disks) trains in a staging folder
<worker tmp>/robot_hoi_ray/<token>/<group>, returns that folder as a tar archive (without references/, the
retarget cache any node rebuilds in seconds) and deletes it; the driver unpacks the archive into RUN/<group>/ file
by file with atomic renames, so the group folder then mirrors the worker's (its references/ kept). --storage
shared|local skips the detection: shared fails loudly on a worker that cannot see the run folder, local always
ships archives. Without shared storage the worker also mirrors its folder to the driver after every periodic
checkpoint (only the files that changed, through a small actor pinned to the driver's node), so a retry on any
node resumes from the last checkpoint: it keeps its staging folder if Ray re-runs it on the same node, else it
starts from the driver's mirror. With --resume the driver first sends its copy of the group folder to the worker.
(Under Ray Client the driver runs off the cluster: no mirror, and a retry elsewhere restarts that teacher.)

Cluster nodes need robot-hoi installed at the same commit (`pip install -e .[cluster]`); clips travel with the
task, so clip files need to exist only on the driver.
"""

from __future__ import annotations

import copy
import io
import logging
import os
import shutil
import socket
import tarfile
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from deploy.atomic import atomic_write_text
from robot_hoi.errors import UserError
from robot_hoi.rl.checkpoint import latest_checkpoint
from robot_hoi.rl.teacher_job import (
    TeacherJob,
    format_line,
    read_job_state,
    train_teacher_group,
)

TOKEN_FILE = ".ray_run_token"
STORAGE_MODES = ("auto", "shared", "local")
NOT_SHIPPED = ("references",)  # top-level entries of a group folder left out of archives (rebuilt on demand)
STAGING_DIRNAME = "robot_hoi_ray"
INCOMING_DIRNAME = ".ray_incoming"  # under RUN/: one level down, so readers of RUN/<group>/ never see it


@dataclass
class RayOptions:
    address: str | None = None  # None: start a local Ray instance (unless this process already runs one)
    cpus_per_teacher: float = 1.0
    gpus_per_teacher: float | None = None  # None: 1 when the cluster has GPUs, else 0
    max_retries: int = 3
    storage: str = "auto"  # one of STORAGE_MODES


# --- worker side ------------------------------------------------------------------------------------------------
def teacher_task(job: TeacherJob, clips: list, storage: str, seed_archive: bytes | None = None,
                 mirror=None) -> dict[str, Any]:
    """Body of one Ray task: train the group where the driver can get at it (see the module docstring)."""
    import ray  # optional: the cluster extra (pip install -e .[cluster])

    clips = copy.deepcopy(clips)  # arguments arrive as read-only zero-copy arrays from the object store
    try:
        if job.device == "cpu" and ray.get_gpu_ids():
            job = replace(job, device="cuda")  # Ray sets CUDA_VISIBLE_DEVICES to this task's GPU(s)
        shared = sees_driver_folder(Path(job.run_dir).parent, job.run_token)
        if storage == "shared" and not shared:
            raise UserError(f"{Path(job.run_dir).parent}: run folder not visible on worker {socket.gethostname()} "
                            f"(no matching {TOKEN_FILE}); mount it on every node or use --storage auto/local")
        if shared and storage != "local":
            return {**train_teacher_group(job, clips), "storage": "shared"}
        staging = staging_dir(job)
        _prepare_staging(staging, job.run_token, seed_archive, mirror, job.group)
        if mirror is None:
            summary = train_teacher_group(job.at(staging), clips)
            summary.update(storage="local", archive=pack_folder(staging))
        else:
            sync = FolderSync(staging, lambda archive, present: ray.get(mirror.put.remote(job.group, archive,
                                                                                           present)))
            summary = train_teacher_group(job.at(staging), clips, on_checkpoint=sync)
            sync()  # the final checkpoint and eval.json
            summary.update(storage="local")
        shutil.rmtree(staging, ignore_errors=True)
        _remove_if_empty(staging.parent)  # the invocation's folder, once its last group has gone
        return summary
    except Exception as exc:
        if getattr(exc, "user_error", False):
            return {"group": job.group, "user_error": str(exc)}  # returned, so Ray does not retry it
        raise


def sees_driver_folder(out_dir: Path, token: str) -> bool:
    try:
        return (out_dir / TOKEN_FILE).read_text().strip() == token
    except OSError:
        return False


def staging_dir(job: TeacherJob) -> Path:
    return Path(tempfile.gettempdir()) / STAGING_DIRNAME / job.run_token / job.group


def _remove_if_empty(folder: Path) -> None:
    try:
        folder.rmdir()
    except OSError:
        pass  # not empty (another group of this run) or already gone


def _prepare_staging(staging: Path, token: str, seed_archive: bytes | None, mirror=None, group: str = "") -> None:
    """Keep a staging folder this invocation already trained in (a retry on the same node); else start it from
    the driver's mirror of this invocation's checkpoints (a retry on another node), else from the driver's copy
    (--resume), else empty."""
    import ray  # optional: the cluster extra (pip install -e .[cluster])

    state = read_job_state(staging)
    if state is not None and state["run_token"] == token:
        return
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    mirrored = ray.get(mirror.get.remote(group)) if mirror is not None else None
    for archive in (mirrored, seed_archive):
        if archive is not None:
            unpack_into(archive, staging)
            return


class FolderSync:
    """Worker side of the mirror: pushes the files of `folder` that changed since the last push (by size and
    mtime), with the list of all files present so that the driver drops what the worker pruned."""

    def __init__(self, folder: Path, push) -> None:
        self.folder = Path(folder)
        self.push = push  # push(archive: bytes, present: list[str])
        self.sent: dict[str, tuple[int, int]] = {}

    def __call__(self, _checkpoint: Path | None = None) -> None:
        files = {}
        for rel in shipped_files(self.folder):
            stat = (self.folder / rel).stat()
            files[rel] = (stat.st_size, stat.st_mtime_ns)
        changed = [rel for rel, signature in files.items() if self.sent.get(rel) != signature]
        self.push(pack_folder(self.folder, only=changed), sorted(files))
        self.sent = files


class CheckpointMirror:
    """Driver-node side of the mirror (a Ray actor pinned to the driver's node): serialises the workers' pushes
    into RUN/<group>/ and hands this invocation's copy to a retry."""

    def __init__(self, out_dir: str, token: str) -> None:
        self.out_dir = Path(out_dir)
        self.token = token

    def put(self, group: str, archive: bytes, present: list[str]) -> None:
        unpack_into(archive, self.out_dir / group, present=set(present))

    def get(self, group: str) -> bytes | None:
        folder = self.out_dir / group
        state = read_job_state(folder)
        if state is None or state["run_token"] != self.token or latest_checkpoint(folder) is None:
            return None
        return pack_folder(folder)


# --- moving group folders ---------------------------------------------------------------------------------------
def shipped_files(folder: Path, skip: tuple[str, ...] = NOT_SHIPPED) -> list[str]:
    """Relative paths of the folder's files that travel: not the top-level entries in `skip`, not hidden files
    (atomic writes' temporaries)."""
    files = []
    for path in sorted(Path(folder).rglob("*")):
        rel = path.relative_to(folder)
        if rel.parts[0] in skip or any(part.startswith(".") for part in rel.parts) or not path.is_file():
            continue
        files.append(rel.as_posix())
    return files


def pack_folder(folder: Path, skip: tuple[str, ...] = NOT_SHIPPED, only: list[str] | None = None) -> bytes:
    """The folder's shipped files (or just `only` of them) as an uncompressed tar (checkpoints are float
    tensors: gzip buys little)."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        for rel in shipped_files(folder, skip) if only is None else only:
            tar.add(Path(folder) / rel, arcname=rel, recursive=False)
    return buffer.getvalue()


def unpack_into(archive: bytes, target: Path, keep: tuple[str, ...] = NOT_SHIPPED,
                present: set[str] | None = None) -> None:
    """Make `target` mirror the archive: every file lands by an atomic rename, then files the archive lacks go
    (except the top-level entries in `keep`, and the files listed in `present`: an incremental archive ships
    only what changed). A crash part-way leaves whole files only."""
    target = Path(target)
    incoming_root = target.parent / INCOMING_DIRNAME
    incoming_root.mkdir(parents=True, exist_ok=True)
    incoming = Path(tempfile.mkdtemp(dir=incoming_root, prefix=f"{target.name}-"))
    try:
        with tarfile.open(fileobj=io.BytesIO(archive), mode="r:") as tar:
            tar.extractall(incoming, filter="data")  # "data": no absolute paths, no escaping links
        arrived = {p.relative_to(incoming) for p in incoming.rglob("*") if p.is_file()}
        for rel in sorted(arrived):
            (target / rel).parent.mkdir(parents=True, exist_ok=True)
            os.replace(incoming / rel, target / rel)
        for path in sorted(target.rglob("*"), reverse=True):
            rel = path.relative_to(target)
            if rel.parts[0] in keep or rel in arrived or (present is not None and rel.as_posix() in present):
                continue
            if path.is_file() or path.is_symlink():
                path.unlink()
            elif path.is_dir() and not any(path.iterdir()):
                path.rmdir()
    finally:
        shutil.rmtree(incoming, ignore_errors=True)
        _remove_if_empty(incoming_root)


# --- driver side ------------------------------------------------------------------------------------------------
def run_teachers(jobs: list[TeacherJob], clips: list[list], options: RayOptions, resume: bool = False,
                 log=print) -> tuple[dict[str, dict], dict[str, str]]:
    """Train every job as a Ray task; gather results into each job's run_dir.

    Returns (summaries of the teachers that finished, {group: error} of those that failed after all retries).
    Uses the Ray instance this process is connected to, else connects to options.address or starts a local one
    (and shuts it down at the end)."""
    import ray  # optional: the cluster extra (pip install -e .[cluster])

    if options.storage not in STORAGE_MODES:
        raise UserError(f"--storage must be one of {', '.join(STORAGE_MODES)}, not {options.storage!r}")
    if options.max_retries < 0 or options.cpus_per_teacher <= 0:
        raise UserError("--max-retries must be >= 0 and --cpus-per-teacher positive")
    out_dirs = {Path(job.run_dir).parent for job in jobs}
    if len(out_dirs) != 1 or len({job.run_token for job in jobs}) != 1:
        raise ValueError("jobs of one call share the run folder and the run token")
    out_dir = out_dirs.pop()
    started_here = not ray.is_initialized()
    if started_here:
        try:
            ray.init(address=options.address, include_dashboard=False, logging_level=logging.WARNING)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            raise UserError(f"Ray at {options.address or 'a new local instance'}: {exc}") from None
    pending: dict = {}
    mirror = None
    try:
        resources = ray.cluster_resources()
        gpus = options.gpus_per_teacher
        if gpus is None:
            gpus = 1.0 if resources.get("GPU", 0.0) >= 1.0 else 0.0
        for kind, need in (("CPU", options.cpus_per_teacher), ("GPU", gpus)):
            if need > resources.get(kind, 0.0):
                raise UserError(f"each teacher asks for {need:g} {kind} but the Ray cluster has "
                                f"{resources.get(kind, 0.0):g}; lower --{kind.lower()}s-per-teacher")
        out_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out_dir / TOKEN_FILE, jobs[0].run_token + "\n")
        task = ray.remote(teacher_task)
        mirror = _start_mirror(out_dir, jobs[0].run_token) if options.storage != "shared" else None
        for job, group_clips in zip(jobs, clips, strict=True):
            job = _for_worker(job, options)
            seed = None
            if resume and options.storage != "shared" and latest_checkpoint(Path(job.run_dir)) is not None:
                seed = pack_folder(Path(job.run_dir))
            ref = task.options(num_cpus=options.cpus_per_teacher, num_gpus=gpus, max_retries=options.max_retries,
                               retry_exceptions=True, name=f"teacher:{job.group}").remote(
                job, group_clips, options.storage, seed, mirror)
            pending[ref] = job
        log(f"ray: {len(jobs)} teacher task(s), {options.cpus_per_teacher:g} CPU + {gpus:g} GPU each, on a "
            f"cluster of {resources.get('CPU', 0):g} CPUs / {resources.get('GPU', 0):g} GPUs")
        return _gather(pending, len(jobs), log)
    finally:
        for ref in pending:  # interrupted: do not leave teachers running on a shared cluster
            ray.cancel(ref, force=True)
        if mirror is not None:
            ray.kill(mirror)
        (out_dir / TOKEN_FILE).unlink(missing_ok=True)
        if started_here:
            ray.shutdown()


def _start_mirror(out_dir: Path, token: str):
    """The CheckpointMirror actor on this (the driver's) node; None under Ray Client (the driver is off-cluster)."""
    import ray  # optional: the cluster extra (pip install -e .[cluster])
    from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

    if ray.util.client.ray.is_connected():
        return None
    here = NodeAffinitySchedulingStrategy(node_id=ray.get_runtime_context().get_node_id(), soft=False)
    return ray.remote(CheckpointMirror).options(num_cpus=0, scheduling_strategy=here).remote(
        str(out_dir.resolve()), token)


def _for_worker(job: TeacherJob, options: RayOptions) -> TeacherJob:
    """No progress bars in workers (the driver prints lines); the physics pool sized to the task's CPUs."""
    train_cfg = copy.deepcopy(job.train_cfg)
    train_cfg.runner.progress = False
    env_cfg = job.env_cfg
    if env_cfg.nthread is None:
        env_cfg = copy.deepcopy(env_cfg)
        env_cfg.nthread = max(int(options.cpus_per_teacher), 1)
    return replace(job, train_cfg=train_cfg, env_cfg=env_cfg)


def _gather(pending: dict, total: int, log) -> tuple[dict[str, dict], dict[str, str]]:
    import ray  # optional: the cluster extra (pip install -e .[cluster])

    summaries: dict[str, dict] = {}
    failures: dict[str, str] = {}
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        for ref in ready:
            job = pending.pop(ref)
            count = f"[{len(summaries) + len(failures) + 1}/{total}]"
            try:
                result = ray.get(ref)
            except ray.exceptions.RayError as exc:
                failures[job.group] = _last_line(exc)
                log(f"{count} {job.group}: FAILED after retries: {failures[job.group]}")
                continue
            if "user_error" in result:
                failures[job.group] = result["user_error"]
                log(f"{count} {job.group}: error: {result['user_error']}")
                continue
            archive = result.pop("archive", None)
            if archive is not None:
                unpack_into(archive, Path(job.run_dir))
            summaries[job.group] = result
            log(f"{count} {format_line(result)}")
    return summaries, failures


def _last_line(exc: BaseException) -> str:
    lines = [line for line in str(exc).strip().splitlines() if line.strip()]
    return lines[-1].strip() if lines else type(exc).__name__
