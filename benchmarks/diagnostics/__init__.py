"""Diagnostic studies of issue 13 (Acrobot-v1): candidate fixes measured with the benchmark's protocol."""
