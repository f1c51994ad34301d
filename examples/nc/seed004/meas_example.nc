%meas_example
:
;Measuring probe tool
;with radius 2 mm
D1
F1000 ;feed: the seed's fragment elides this block with ':'
G0 X150 Z200
G100 Z20
:
M30
