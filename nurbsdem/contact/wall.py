"""placeholder"""
def detect_wall(*a, **k):
    raise NotImplementedError
