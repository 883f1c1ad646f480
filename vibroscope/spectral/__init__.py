"""vibroscope.spectral"""
