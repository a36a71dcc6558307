"""Many captures at once: :func:`measure_batch` (``mifaces batch``) on Dask.

Each capture is one task, :func:`measure_one`, that runs
:func:`mifaces.pipeline.measure.measure` into ``OUT/.<name>.partial`` and renames
the folder to ``OUT/<name>`` once it is complete, so ``OUT/<name>`` holds
exactly what ``mifaces measure`` writes, or nothing. The tasks run on a
``dask.distributed`` cluster: a :class:`~distributed.LocalCluster` of
worker processes by default, or any running Dask scheduler given by its
address (``dask scheduler`` + ``dask worker`` on a cluster, a job queue,
Kubernetes: no code changes). Worker processes are reused from capture to
capture, so each imports mifaces once and keeps its face-model cache and
Dr.Jit's kernel cache warm.

Dr.Jit runs its own thread pool in every process. So that workers do not
oversubscribe the cores, each worker process takes one task at a time and
:class:`WorkerSetup` gives its Dr.Jit pool ``cores // task slots on the
host`` threads (:func:`drjit.set_thread_count`).

Every capture is measured with the same :class:`~mifaces.options.measure.MeasureOptions`, sent
whole to the workers and recorded whole in ``batch.json`` and each ``report.json``; ``resume``
skips a capture only if its report records these options, and measures one fitted with other
options again.

A capture that fails (a corrupt manifest, a fit that diverges, a worker
that dies) is recorded with its error in ``OUT/batch.json``; the others go
on. Once all have finished, :func:`mifaces.report.population.write_population`
writes the population report ``OUT/population.{md,json,png}`` over every
complete capture of the batch. See ``docs/scaling.md``.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import os
import shutil
import socket
import time
import traceback
import uuid
from dataclasses import dataclass
from pathlib import Path

import mifaces  # noqa: F401  # first: it points Dr.Jit at libLLVM; workers import it once, on unpickling a task

import dask
import drjit as dr
import mitsuba as mi
from distributed import Client, KilledWorker, LocalCluster, WorkerPlugin, as_completed
from distributed.comm import get_address_host
from tqdm import tqdm

from ..capture.types import MANIFEST
from ..io.atomic import write_json
from ..importers.yaleb import import_subject
from ..options.fields import check, option
from ..options.measure import MeasureOptions
from .measure import measure
from ..report.population import write_population
from ..runtime.progress import progress as progress_bar

#: Readers of raw data sets, by the name ``mifaces batch --import`` takes:
#: ``(source folder, capture folder to write, force=True) -> capture folder``.
IMPORTERS = {"yaleb": import_subject}
#: The batch's record: options, and every capture's status, error and times.
RECORD = "batch.json"
#: Folder of the batch's output holding the captures its importer wrote.
IMPORTED = "captures"
#: A capture's status in the record.
DONE, SKIPPED, FAILED, PENDING = "done", "skipped", "failed", "pending"
#: Times Dask reruns a capture whose worker died before calling it failed.
RETRIES = 1


def _cores() -> int:
    """CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        return os.cpu_count() or 1


def _is_yale_subject(folder: Path) -> bool:
    return any(folder.glob("*_P00A*E*.pgm"))


def find_captures(inputs, importer: str | None = None) -> dict[str, Path]:
    """The captures of ``inputs``, by name.

    Parameters
    ----------
    inputs : sequence of path
        Capture folders (holding ``capture.json``) or folders of them; with
        ``importer='yaleb'``, Yale subject folders or folders of them.
    importer : {None, 'yaleb'}

    Returns
    -------
    dict
        ``{name: folder}``: a capture is named by its folder, prefixed with
        its parents' names (``seed3-capture``) where names would repeat.

    Raises
    ------
    FileNotFoundError
        For an input that is none of these.
    ValueError
        For an unknown importer.
    """
    if importer is not None and importer not in IMPORTERS:
        raise ValueError(f"unknown importer {importer!r}; choose from {sorted(IMPORTERS)}")
    is_capture = _is_yale_subject if importer else (lambda folder: (folder / MANIFEST).is_file())
    what = "Yale subject (*_P00A*E*.pgm)" if importer else f"capture ({MANIFEST})"
    folders = []
    for given in map(Path, inputs):
        if not given.is_dir():
            raise FileNotFoundError(f"{given} is not a folder")
        found = [given] if is_capture(given) else sorted(c for c in given.iterdir() if c.is_dir() and is_capture(c))
        if not found:
            raise FileNotFoundError(f"no {what} in {given} or its sub-folders")
        folders += [folder.resolve() for folder in found if folder.resolve() not in folders]
    return dict(zip(_unique_names(folders), folders))


def _unique_names(folders: list[Path]) -> list[str]:
    """Each folder's name, prefixed with as many parent names as it takes to tell them apart."""
    depth = 1
    while True:
        names = ["-".join(folder.parts[-depth:]).lstrip("-/") for folder in folders]
        if len(set(names)) == len(names) or depth >= max(len(f.parts) for f in folders):
            return names
        depth += 1


def is_complete(folder: Path, capture: Path, options: MeasureOptions) -> bool:
    """Whether ``folder`` holds a finished measurement of ``capture`` with ``options``:
    ``report.json`` readable, naming the same capture and recording these options (its
    ``options.requested``, read by :meth:`MeasureOptions.from_record
    <mifaces.options.measure.MeasureOptions.from_record>`: all of them, not only the models),
    and the report's other files and every model's ``brdf.json`` present."""
    try:
        report = json.loads((folder / "report.json").read_text())
        same = (Path(report["capture"]).resolve() == Path(capture).resolve()
                and MeasureOptions.from_record(report["options"]["requested"]) == options)
    except (OSError, ValueError, KeyError, TypeError):  # a report of other options, or of none
        return False
    files = [folder / "report.md", folder / "report.png"] + [folder / "brdf" / m / "brdf.json" for m in options.models]
    return same and all(f.is_file() for f in files)


def _replace_folder(source: Path, target: Path) -> None:
    """Rename folder ``source`` to ``target``, replacing any folder there."""
    if target.exists():
        old = target.with_name(f".{target.name}.old")
        shutil.rmtree(old, ignore_errors=True)
        os.replace(target, old)
        os.replace(source, target)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(source, target)


def measure_one(name: str, source, out, importer: str | None = None, options: MeasureOptions | None = None) -> dict:
    """The task of one capture: import it if asked, :func:`mifaces.pipeline.measure.measure`
    it into ``out/.<name>.partial``, and rename that to ``out/<name>``.

    Returns
    -------
    dict
        The capture's entry in ``batch.json``: ``status`` (``done`` or
        ``failed``), ``error`` and ``traceback`` when it failed, ``capture``,
        ``seconds`` (the task, import included), ``measure_seconds``,
        ``worker`` (host and process id). Never raises for a failed capture.
    """
    t0 = time.perf_counter()
    out = Path(out)
    partial, final = out / f".{name}.partial", out / name
    entry = {"worker": f"{socket.gethostname()}:{os.getpid()}"}
    try:
        capture = Path(source)
        if importer is not None:
            capture = IMPORTERS[importer](source, out / IMPORTED / name, force=True)
        entry["capture"] = str(capture)
        shutil.rmtree(partial, ignore_errors=True)
        report = measure(partial, capture, options, progress=False)
        _replace_folder(partial, final)
        entry.update(status=DONE, measure_seconds=report["seconds"]["total"])
    except Exception as error:  # recorded, and the batch goes on
        entry.update(status=FAILED, error=f"{type(error).__name__}: {error}", traceback=traceback.format_exc())
        if partial.exists():
            entry["partial"] = str(partial)
    entry["seconds"] = time.perf_counter() - t0
    return entry


class WorkerSetup(WorkerPlugin):
    """Prepares each worker process once: the Mitsuba variant, and Dr.Jit's
    thread count so that the task slots on a host share its cores.

    Parameters
    ----------
    variant : str
        Mitsuba variant of the measurements.
    slots : dict
        ``{host: task slots on the host}`` (the sum of its workers' threads);
        a worker of a host not named takes its own thread count.
    """

    name = "mifaces-worker-setup"

    def __init__(self, variant: str, slots: dict[str, int]):
        self.variant, self.slots = variant, dict(slots)

    def setup(self, worker) -> None:
        mifaces.set_variant(self.variant)
        slots = self.slots.get(get_address_host(worker.address), worker.state.nthreads)
        dr.set_thread_count(max(1, _cores() // max(1, slots)))


def _slots(client: Client) -> dict[str, int]:
    slots = {}
    for address, info in client.scheduler_info()["workers"].items():
        host = get_address_host(address)
        slots[host] = slots.get(host, 0) + info["nthreads"]
    return slots


@contextlib.contextmanager
def cluster_client(workers: int | None = None, scheduler: str | None = None, tasks: int = 1, wait: float = 120.0):
    """A Dask client: of the scheduler at address ``scheduler`` (or of the
    scheduler file at that path), else of a new :class:`~distributed.LocalCluster`
    of ``workers`` processes (default: one per core, at most ``tasks``), one
    task slot each. Waits up to ``wait`` seconds for a first worker."""
    cluster = None
    if scheduler:
        client = Client(scheduler_file=scheduler) if Path(scheduler).is_file() else Client(scheduler)
    else:
        with dask.config.set({"distributed.scheduler.allowed-failures": RETRIES}):
            cluster = LocalCluster(n_workers=workers or max(1, min(_cores(), tasks)), threads_per_worker=1,
                                   processes=True)
        client = Client(cluster)
    try:
        try:
            client.wait_for_workers(1, timeout=wait)
        except TimeoutError:
            raise TimeoutError(f"no Dask worker joined the scheduler {client.scheduler.address} within "
                               f"{wait:.0f} s; start some with `dask worker {client.scheduler.address}`") from None
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@dataclass(frozen=True)
class Cluster:
    """Where a batch's tasks run (:func:`cluster_client`): a new local Dask cluster, or a running
    scheduler; and the Mitsuba variant of its workers. Validated on construction (a ``ValueError``
    naming the field).

    Attributes
    ----------
    workers : int, optional
        Worker processes of the local cluster (default: one per core, at most one per capture).
    scheduler : str, optional
        Address (``tcp://host:port``) or scheduler file of a running Dask
        scheduler to use instead of a local cluster.
    variant : str, optional
        Mitsuba variant of the workers (default: the current one).
    """

    workers: int | None = option(None, bounds=(1, None))
    scheduler: str | None = None
    variant: str | None = None

    def __post_init__(self):
        check(self)

    def client(self, tasks: int):
        """:func:`cluster_client` of this cluster, for ``tasks`` tasks (a context manager)."""
        return cluster_client(self.workers, self.scheduler, tasks)


def dashboard(client: Client) -> str:
    """The line naming the Dask dashboard's address, or why there is none."""
    if "dashboard" not in client.scheduler_info().get("services", {}):
        return "Dask dashboard: none (the scheduler serves none)"
    if importlib.util.find_spec("bokeh") is None:
        return f"Dask dashboard: not available (bokeh is not installed; with it, {client.dashboard_link})"
    return f"Dask dashboard: {client.dashboard_link}"


def measure_batch(inputs, out, options: MeasureOptions | None = None, *, cluster: Cluster | None = None,
                  resume: bool = False, importer: str | None = None, progress: bool = True, echo=None,
                  **keywords) -> dict:
    """Measure many captures on Dask, each as :func:`mifaces.pipeline.measure.measure` would.

    Parameters
    ----------
    inputs : sequence of path
        Captures or folders of them (:func:`find_captures`).
    out : path
        Batch folder: ``<name>/`` per capture, ``batch.json``, ``population.{md,json,png}``
        (and ``captures/<name>/`` with an importer).
    options : MeasureOptions, optional
        How every capture is measured (:func:`mifaces.pipeline.measure.measure`), sent whole to the workers.
    cluster : Cluster, optional
        Where the tasks run (:class:`Cluster`; default: a local cluster of one worker per core, at
        most one per capture, in the current Mitsuba variant).
    resume : bool
        Skip captures whose results in ``out`` are complete and record ``options``
        (:func:`is_complete`); measure those fitted with other options again.
    importer : {None, 'yaleb'}
        Import raw data first (:data:`IMPORTERS`).
    **keywords
        Options as keywords, applied over ``options`` as :func:`mifaces.pipeline.measure.measure` takes them
        (``models=``, ``geometry=``, ``spp=``, ...; :meth:`MeasureOptions.of
        <mifaces.options.measure.MeasureOptions.of>`).
    progress : bool
        A bar over the captures.
    echo : callable, optional
        Called with a line per finished capture and the dashboard's address.

    Returns
    -------
    dict
        The record, also written as ``out/batch.json``: ``options`` (:meth:`MeasureOptions.to_record
        <mifaces.options.measure.MeasureOptions.to_record>`),
        ``captures`` (``{name: entry}``, see :func:`measure_one`),
        ``failed`` (names), ``seconds``, ``throughput_per_hour``, ``population``.
    """
    t0 = time.perf_counter()
    echo = echo or (lambda line: None)
    out = Path(out).resolve()
    options = MeasureOptions.of(options, keywords, "measure_batch")  # validated before any worker starts
    cluster = Cluster() if cluster is None else cluster
    captures = find_captures(inputs, importer)
    record = {"out": str(out), "importer": importer, "options": options.to_record(),
              "captures": {name: {"source": str(source), "status": PENDING} for name, source in captures.items()}}
    todo = {}
    for name, source in captures.items():
        capture = out / IMPORTED / name if importer else source
        if resume and is_complete(out / name, capture, options):
            record["captures"][name].update(status=SKIPPED, capture=str(capture))
        else:
            todo[name] = source
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / RECORD, record)
    if todo:
        _run(todo, out, importer, options, cluster, record, progress, echo)
    record["failed"] = [name for name, entry in record["captures"].items() if entry["status"] != DONE
                        and entry["status"] != SKIPPED]
    record["seconds"] = time.perf_counter() - t0
    measured = sum(entry["status"] == DONE for entry in record["captures"].values())
    record["throughput_per_hour"] = 3600.0 * measured / record["seconds"] if measured else 0.0
    complete = {name: out / name / "report.json" for name, entry in record["captures"].items()
                if entry["status"] in (DONE, SKIPPED)}
    record["population"] = write_population(out, complete, record) if complete else None
    write_json(out / RECORD, record)
    return record


def _run(todo: dict, out: Path, importer, options: MeasureOptions, cluster: Cluster, record: dict, progress: bool,
         echo) -> None:
    """Submit ``todo`` to the cluster; record each capture as it finishes."""
    with cluster.client(len(todo)) as client:
        echo(dashboard(client))
        client.register_plugin(WorkerSetup(cluster.variant or mi.variant(), _slots(client)))
        run = uuid.uuid4().hex[:8]
        futures = {client.submit(measure_one, name, str(source), str(out), importer, options,
                                 key=f"mifaces-measure-{name}-{run}", pure=False): name
                   for name, source in todo.items()}
        bar = progress_bar(total=len(todo), desc="batch", unit="capture", enabled=progress)
        for future in as_completed(futures):
            name = futures[future]
            try:
                entry = future.result()
            except KilledWorker as error:
                entry = {"status": FAILED, "error": f"the worker process measuring it died (KilledWorker): {error}"}
            except Exception as error:  # the task could not run (unpicklable arguments, a cancelled future)
                entry = {"status": FAILED, "error": f"{type(error).__name__}: {error}"}
            record["captures"][name].update(entry)
            write_json(out / RECORD, record)
            line = _line(name, record["captures"][name])
            if isinstance(bar, tqdm):
                bar.write(line)  # above the bar, on a terminal
            else:
                echo(line)
            bar.update()
        bar.close()


def _line(name: str, entry: dict) -> str:
    if entry["status"] == DONE:
        return f"{name}: done in {entry['seconds']:.1f} s ({entry['worker']})"
    return f"{name}: FAILED: {' '.join(entry['error'].split())}"


__all__ = ["measure_batch", "Cluster", "measure_one", "find_captures", "is_complete", "cluster_client", "WorkerSetup",
           "IMPORTERS", "RECORD"]
