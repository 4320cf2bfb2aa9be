"""Studies at scale: ``lapwrench sweep`` (many seeded runs of the scenarios over a parameter space,
on Ray, to a Parquet table and a report) and ``lapwrench tune`` (Ray Tune searching gains for an
objective under constraints).

Layers: :mod:`.space` (parameter keys and distributions) → :mod:`.spec` (the study file, its jobs) →
:mod:`.execute` (one job, no Ray) → :mod:`.table` (the Parquet table) → :mod:`.runner` (Ray) and
:mod:`.tune`; :mod:`.report` writes the Markdown and PNGs; :mod:`.cli` wires the commands.
Ray, pandas and pyarrow come with the ``study`` extra, installed on first use (:mod:`.setup`).
"""
