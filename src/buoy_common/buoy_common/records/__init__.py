"""Logger records into the contract: column maps (:mod:`.column_map`) and decoding
(:mod:`.decoding`); the command is :mod:`buoy_common.import_records`."""
