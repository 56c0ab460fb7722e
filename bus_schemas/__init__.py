"""The AMPRO3-style CAN protocol (DBC), its codec, zenoh key expressions, MCAP channel
schemas and the python-can interface that carries CAN frames over zenoh.

Modules: :mod:`~bus_schemas.protocol` (DBC, ids, enums, steps), :mod:`~bus_schemas.crc8`,
:mod:`~bus_schemas.codec` (encode/decode/quantize, ``FrameChecker``),
:mod:`~bus_schemas.keys`, :mod:`~bus_schemas.zenoh_config`, :mod:`~bus_schemas.zenoh_can`
(``ZenohBus``), :mod:`~bus_schemas.mcap_schemas` (``Recorder``). See ``README.md`` here.
Nothing is imported eagerly: ``import bus_schemas`` stays cheap.
"""
