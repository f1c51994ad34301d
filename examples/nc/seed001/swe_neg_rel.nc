%swe_rel.nc
N110 G00 X0 Y0 G90
N120 G00 X20 Y30

(Offsets neg. SLS in X by 10 and Y by 20)
N130 G98 G91 X10 Y20

( .... )
N140 #MSG SYN["neg. SLS X=%f Y=%f", V.A.-SWE.X, V.A.-SWE.Y]
N150 M30
