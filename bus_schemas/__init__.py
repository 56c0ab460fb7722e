"""The AMPRO3-style CAN protocol (DBC), its codec, zenoh key expressions, MCAP channel
schemas and the python-can interface that carries CAN frames over zenoh.
"""
