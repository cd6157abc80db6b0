"""The development subcommands of ``protoduino`` (gen, soak), found by protoduino.cli.main."""
