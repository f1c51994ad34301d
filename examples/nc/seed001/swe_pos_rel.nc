%swe_rel.nc
N110 G00 X0 Y0 G90
N120 G00 X20 Y30

(Offsets pos. SLS in X by -10 and Y by -20)
N130 G99 G91 X-10 Y-20

(....)
N140 #MSG SYN["pos. SLS X=%f Y=%f", V.A.+SWE.X, V.A.+SWE.Y]
N150 M30
