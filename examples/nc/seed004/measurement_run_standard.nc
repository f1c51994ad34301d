%Measurement run standard
N10 G00 X0 Y1 Z0
N20 X5
N30 G100 X10 F500
                        ;Wait for probing signal from X
N40 G01 Y3
                        ;Wait for probing signal from Y
N50 G100 Y10 F500
N60 G01 X10 Y5
N70 G100 X15 Y10 F500
                        ;Wait for probing signal from X & Y
N100 M30
