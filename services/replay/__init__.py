"""Replay: playback of a recording into a live graph, and resim (recorded inputs → services →
outputs diffed against the recording)."""
