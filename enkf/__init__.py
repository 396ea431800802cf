"""Ensemble Kalman filtering: a generic filter (pure array math) and the
tissue-identification application that drives it with the laser-tissue model.
"""
