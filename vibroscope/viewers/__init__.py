"""vibroscope.viewers"""
