"""The transport: the AMPRO3-style CAN protocol (a DBC), its codec, and CAN frames carried
between processes over zenoh (or over any python-can bus).

Modules: :mod:`.protocol` (DBC, ids, enums, steps, bus load), :mod:`.crc8`, :mod:`.frame`
(the light ``Frame``), :mod:`.codec` (encode/decode/quantize, ``FrameChecker``),
:mod:`.keys` (zenoh key expressions), :mod:`.zenoh_config` (loopback-only session config),
:mod:`.wire` (frames and frame batches as zenoh payloads), :mod:`.receiver` (zenoh
subscribers with timeouts), :mod:`.zenoh_can` (``ZenohBus``, the ``zenoh`` python-can
interface), :mod:`.liveliness` (the ``Liveliness`` protocol), :mod:`.bus_config`
(``BusConfig``, ``make_bus``, ``send_frames``, ``FrameReader``), :mod:`.run_auth`
(per-run credentials). The controller process imports these: none loads ``hp_model``, and
nothing is imported eagerly here.
"""
