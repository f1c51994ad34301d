%swe_extend.nc
;Assuming: Software limit switches are configured to +- 200 in X, Y
;(run with --machine examples/machines/xy200.toml)
N5 F6000 ;feed, not part of the seed's fragment (G01 needs one)
N10 G01 G90 X199
N20 #MSG SYN["SLS X [%f, %f] Y [%f, %f]", V.A.-SWE.X, V.A.+SWE.X, V.A.-SWE.Y, V.A.+SWE.Y]
N100 G98 X-500 Y-500 ;neg. Software limit switches X and Y -> -500
N200 G99 X500 Y500 ;pos. Software limit switches X and Y -> +500
N210 #MSG SYN["SLS X [%f, %f] Y [%f, %f]", V.A.-SWE.X, V.A.+SWE.X, V.A.-SWE.Y, V.A.+SWE.Y]
N300 G01 X450 Y450 ;Move within extended section
N310 #MSG SYN["at X=%f Y=%f", V.A.ABS.X, V.A.ABS.Y]
N400 G01 X100 Y100 ;Back to limited section
N500 G98 X-200 Y-200 ;neg. Software limit switches X and Y -> -200
N600 G99 X200 Y200 ;pos. Software limit switches X and Y -> 200
N610 #MSG SYN["SLS X [%f, %f] Y [%f, %f]", V.A.-SWE.X, V.A.+SWE.X, V.A.-SWE.Y, V.A.+SWE.Y]
N700 M30
