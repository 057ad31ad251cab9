"""Where the recorded numbers come from: benchmark and study records, fingerprinted.

* :mod:`~depthcore.provenance.benchmarks`: the benchmarks' records, the code
  fingerprints that make a record stale, and the machine a record was made on;
* :mod:`~depthcore.provenance.records`: the book's heavy studies, computed once
  and read back from their records while the pages run;
* :mod:`~depthcore.provenance.closure`: what one study's call runs (the code it
  reaches, the constants it reads, the filters it names), fingerprinted, so that
  its record goes stale only when that changes;
* :mod:`~depthcore.provenance.environment`: the environment of a build (date,
  versions, processor) in one sentence, shared by the article and the book, and
  where the records were computed, read from them.

The records themselves are package data beside these modules
(``benchmark_records/``, ``study_records/``). Where a new thing goes: a new
kind of record, or a new field of the environment a record states, goes here.
It imports no filter: it fingerprints their sources.
"""

from depthcore import _paths


def __getattr__(name):
    return _paths.submodule(__name__, name)
