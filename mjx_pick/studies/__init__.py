"""What a user asks: evaluate pick-points, sweep parameters, compare and design grippers,
robustness and minimum force, calibration and the trials loop, throughput.
"""
