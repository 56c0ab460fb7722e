"""The recording: a run written to MCAP (channel schemas, the :class:`Recorder`) and read
back (decoder factories, ``read_messages``).

Modules: :mod:`.schemas` (JSON-schema channels, ``CHANNELS``, ``FOXGLOVE_CHANNELS``, the
CAN frame record), :mod:`.foxglove` (the Foxglove protobuf classes and descriptor sets),
:mod:`.json_encoding` (``encode_json``: numpy values, NaN/inf as null), :mod:`.reader`
(``JsonDecoderFactory``, ``ProtobufDecoderFactory``, ``read_messages``), :mod:`.recorder`
(``Recorder``: the file, channels, writes, finishing) with :mod:`.deferred` (deferred
writes) and :mod:`.signals` (finishing on SIGTERM/SIGINT), :mod:`.part_file` (the locked
``.part`` file, ``RecordingInUseError``), :mod:`.can_rates` (``/can/rates`` windows),
:mod:`.chunk_append` (one-pack append into mcap's open chunk). It names domains with
``hp_model.domains.Domain`` (so loads ``hp_model``); nothing is imported eagerly here.
"""
