"""DeFT's frame rules, one module each: every module here registers one ``FrameRule`` (see ``frames/rule.py``).

Adding a rule is adding a module (docs/deft.md, "Adding a frame rule");
deleting the module takes the rule out again. Nothing lists the rules by
hand: ``FRAME_RULES`` imports this package's modules on first read.
"""
