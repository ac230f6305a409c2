"""Simulated controller endpoints: serve a virtual CNC run over a real transport."""
