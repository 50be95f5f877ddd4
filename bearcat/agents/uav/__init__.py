"""The UAV agent (MAVSDK client), the MAVLink vehicle emulator and the camera footprint."""
