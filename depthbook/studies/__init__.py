"""The studies only the book runs (``python -m depthcore study`` runs :mod:`depthcore.studies`).

* :mod:`~depthbook.studies.frames`: the study at several numbers of frames;
* :mod:`~depthbook.studies.per_frame`: every filter scored at every frame of
  one set of tracks (RMSE beside the bound, ANEES with its chi-square region,
  track loss at several thresholds);
* :mod:`~depthbook.studies.hardness`: where the problem is hard, across
  parallax, prior and depth;
* :mod:`~depthbook.studies.replication`: a study replicated on independent
  seeds, its stated errors set against the spread across replicates;
* :mod:`~depthbook.studies.claims`: every checkable claim of the paper, each
  decided by a test stated before its number, from the numbers of
  :mod:`~depthbook.studies.evidence`;
* :mod:`~depthbook.studies.verdicts`: the numbers behind the print's errors;
* :mod:`~depthbook.studies.calibration_grid`: simulation-based calibration over
  settings of frames, noise, process noise and the depth's law.

Where a new thing goes: a study a chapter needs that no user of ``depthcore``
runs. A study users run goes to :mod:`depthcore.studies`.
"""
