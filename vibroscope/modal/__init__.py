"""vibroscope.modal"""
