%Meas fixed stop
N010 #MEAS MODE [7]
N020 G0 Z100
; enable torque limiting
NO30 #DRIVE WR SYN [AX=Z KEY=TORQUE LIMIT VAL=10 WAIT]
; disable position lag monitoring in drive
NO40 #DRIVE WR SYN [AX=Z KEY=MON WINDOW VAL=4294967295 WAIT]
; start measurement run
N050 G100 Z1000 F100
; move away from fixed stop
N060 G01 Z100 F1000
; re-enable position lag monitoring
N070 #DRIVE WR SYN [AX=Z KEY=MON WINDOW VAL=1048575 WAIT]
; disable torque limiting
NO80 #DRIVE WR SYN [AX=Z KEY=TORQUE LIMIT VAL=5000 WAIT]
N090 M30
