"""protoduino's benchmarks against its peers; ``python -m bench`` writes docs/performance.md.

Layout, so that a new measurement is a small addition:

* ``core``      shared types: :class:`~bench.core.Section`, :class:`~bench.core.SectionResult`,
                :class:`~bench.core.Target`, :class:`~bench.core.Context`, CPU-time measurement.
* ``registry``  the ordered list of sections the report contains.
* ``peers/``    one module per library (protoduino, pymavlink, Pigweed, pySerialTransfer,
                Firmata, Telemetrix). Each knows how to build a stream for that library, parse it
                and encode the servo command with the library's own code; a missing library
                raises :class:`~bench.core.MissingDependencyError` naming the package to install.
* ``receive``   part 1, the host receive path, with each of protoduino's stream decoders (the C
                accelerator ``protoduino._speedups`` and the pure-Python ``PyStreamDecoder``);
                ``roundtrip`` part 2, command -> Ack latency; ``throughput`` part 3, commands/s
                by window and Ping echo; ``wire`` part 4, bytes on the wire; ``firmware``
                part 5, the Uno build's footprint and cycles per command; ``motion`` part 6,
                ``inputs`` part 7; ``ros2`` part 8, the ROS 2 bridge on the emulated Uno
                (``ros2_peer``: its DDS side, imported only once cyclonedds is known present).
                ``race`` part 9, protoduino against StandardFirmata's unmodified hex on the
                same emulated Uno (``peers/firmata_board``: pyFirmata2 drives it, its
                footprint read from the hex).
* ``boards``    the simulated board and the emulated Uno for parts 2, 3 and 5, the emulator's
                cycle counters and profile (``tools/avrsim --stats/--profile``), and a raw
                pyserial client to tell the host library's share of a round trip.
* ``machine``, ``charts``, ``report``, ``runner``: machine facts, matplotlib charts, the markdown
                writer and the command line (``--only PART --merge`` reruns parts into the
                existing report).

The benchmarks only measure; they never assert on time. ``tests/e2e/test_bench_smoke.py`` runs
every one of them for a few iterations to prove the code runs (the board parts with a handful of
calls; those on the emulated Uno are marked ``avr``).
"""
