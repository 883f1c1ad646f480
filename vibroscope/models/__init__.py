"""vibroscope.models"""
