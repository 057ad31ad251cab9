"""Where the recorded numbers come from: benchmark and study records, fingerprinted.

* :mod:`~depthbook.provenance.benchmarks`: the benchmarks' records, the code
  fingerprints that make a record stale, and the machine a record was made on;
* :mod:`~depthbook.provenance.records`: the book's heavy studies, computed once
  and read back from their records while the pages run;
* :mod:`~depthbook.provenance.closure`: what one study's call runs (the code it
  reaches, the constants it reads, the filters it names), fingerprinted, so that
  its record goes stale only when that changes;
* :mod:`~depthbook.provenance.environment`: the environment of a build (date,
  versions, processor) in one sentence, and where the records were computed.

The records are data beside these modules (``benchmark_records/``,
``study_records/``). Where a new thing goes: a new kind of record, or a new
field of the environment a record states, goes here.
"""
