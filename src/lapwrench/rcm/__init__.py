"""RCM geometry (eq 18, 27-36) and the adaptive RCM point (eq 19-26)."""
