"""The benchmark and verification problems: the seed's two beams (:mod:`.two_beams`), the pressed
blocks of the scaling study (:mod:`.pressed_blocks`), Hertz contact (:mod:`.hertz`) and the sphere
on a block (:mod:`.sphere_on_block`)."""
