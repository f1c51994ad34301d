%hello
; A first program: a square and a circle in the XY plane on the default machine.
N10 G00 G90 X0 Y0 Z0
N20 G01 X50 F3000
N30 Y50
N40 X0
N50 Y0
N60 G02 X0 Y0 I25 J0
N70 #MSG SYN["X=%f Y=%f Z=%f", V.A.ABS.X, V.A.ABS.Y, V.A.ABS.Z]
N80 #MSG SYN["SLS X [%f, %f]", V.A.-SWE.X, V.A.+SWE.X]
N90 M30
