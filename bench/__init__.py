"""protoduino's benchmarks against its peers (issue 7); ``python -m bench`` writes the report.

Layout, so that a new measurement is a small addition:

* ``core``      shared types: :class:`~bench.core.Section`, :class:`~bench.core.SectionResult`,
                :class:`~bench.core.Target`, :class:`~bench.core.Context`, CPU-time measurement.
* ``registry``  the ordered list of sections the report contains. Parts not written yet are
                placeholders there; replacing one is a one-line change.
* ``peers/``    one module per library (protoduino, pymavlink, Pigweed, pySerialTransfer,
                Firmata, Telemetrix). Each knows how to build a stream for that library, parse it
                and encode the servo command with the library's own code; a missing library
                raises :class:`~bench.core.MissingDependencyError` naming the package to install.
* ``receive``   part 1, the host receive path, with each of protoduino's stream decoders (the C
                accelerator ``protoduino._speedups`` and the pure-Python ``PyStreamDecoder``);
                ``wire`` part 4, bytes on the wire.
* ``machine``, ``charts``, ``report``, ``runner``: machine facts, matplotlib charts, the markdown
                writer and the command line.

The benchmarks only measure; they never assert on time. ``tests/test_bench_smoke.py`` runs
every one of them for a few iterations to prove the code runs.
"""
