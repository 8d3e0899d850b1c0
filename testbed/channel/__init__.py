"""simpy link models: bitrate, delay, bit errors, bursts, collisions, buffers, presets."""
