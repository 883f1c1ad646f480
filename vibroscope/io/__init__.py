"""vibroscope.io"""
