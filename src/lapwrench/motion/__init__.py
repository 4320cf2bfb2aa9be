"""Motion generation: the virtual model, its Euler integration and the reference shaper."""
