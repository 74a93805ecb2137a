"""Datasets at scale: sweeps over port tilt and conditions, rendered on Dask, resumable.

* :mod:`~simulator.dataset.spec`: the sweep spec (TOML), its validation and expansion into samples;
* :mod:`~simulator.dataset.run`: running a sweep on a local or distributed Dask cluster, with the
  manifest and resume;
* :mod:`~simulator.dataset.sample`: rendering one sample into its folder (the workers' task);
* :mod:`~simulator.dataset.manifest`: the on-disk layout (``dataset.json``, ``manifest.jsonl``);
* :mod:`~simulator.dataset.check`: verifying a dataset against its manifest;
* :mod:`~simulator.dataset.images`: a sample's images in the dataset's format (EXR, NPZ, 16-bit PNG);
* :mod:`~simulator.dataset.loader`: iterating samples as numpy arrays, for training code.

See docs/datasets.md. Nothing here imports Mitsuba or Dask until a sample is rendered or a run
starts.
"""

from simulator.dataset.check import CheckReport, SampleProblem, check_dataset
from simulator.dataset.loader import ArrayDataset, Dataset, Sample
from simulator.dataset.run import DatasetBusyError, DatasetMismatchError, RunReport, run_dataset
from simulator.dataset.spec import OUTPUTS, SweepSample, SweepSpec, embedded_sweeps, expand, load_spec, parse_spec

__all__ = [
    "OUTPUTS",
    "ArrayDataset",
    "CheckReport",
    "Dataset",
    "DatasetBusyError",
    "DatasetMismatchError",
    "RunReport",
    "Sample",
    "SampleProblem",
    "SweepSample",
    "SweepSpec",
    "check_dataset",
    "embedded_sweeps",
    "expand",
    "load_spec",
    "parse_spec",
    "run_dataset",
]
