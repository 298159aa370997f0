"""External SLAM programs driven step by step over the mapqual-slam protocol.

The protocol: docs/external-slam.md.
"""
