%Measurement run CS
N10 G00 X0 Y1 Z0
N20 #CS ON[0,0,0,0,45]
N30 G100 X10 F500 ; Wait for probing signal from X & Y & Z
N40 #CS OFF
N50 \#CS ON[0,0,0,0,0,90]
N60 G100 X10 F500 ; Wait for probing signal from X & Y & Z
N70 #CS OFF
N100 M30
