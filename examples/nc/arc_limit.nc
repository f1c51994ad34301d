%arc_limit
; Both end points of the half circle lie inside Y <= 200, its apex does not:
; the block is refused in block preparation (P-ERR-120002), nothing moves.
; Run with --machine examples/machines/xy200.toml
N10 G00 G90 X-150 Y150
N20 G02 X150 Y150 I150 J0 F3000
N30 #MSG SYN["not reached"]
N40 M30
