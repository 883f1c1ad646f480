"""vibroscope.gap"""
