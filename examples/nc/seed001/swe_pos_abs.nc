%swe_abs.nc
N110 G00 X0 Y0 G90
N120 G00 X20 Y30

(Sets pos. SLS in X to 100 and Y to 200)
N130 G99 X100 Y200

(....)
N140 #MSG SYN["pos. SLS X=%f Y=%f", V.A.+SWE.X, V.A.+SWE.Y]
N150 M30
