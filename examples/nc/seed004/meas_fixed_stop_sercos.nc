%Meas fixed stop
; Seed 004 §7.3.1 "Measurement run to fixed stop with a gantry system (Soft Gantry)".
; The PDF extraction moved the command words of N040, N050 and N100 below the first line of
; their own brackets; here each block is put back in order, nothing else is changed.
; Run with: --machine examples/machines/gantry.toml --set P-CHAN-00057=7 --fixed-stop-at X=300
; enable SoftGantry
N010 G0 X100 X2=0
N020 #SET AX LINK[1, [X2=X,G,15,20]]
N030 #ENABLE AX LINK[1]
; read values from drives
N040 #IDENT RD     [AXNR 1 ID S-0-0092 P=P1092
                                                TYP 2 DEC 0 SERC]
N050 #IDENT RD     [AXNR 1 ID S-0-0159 P=P1159 TYP 4 DEC 0 SERC]
N060 #IDENT RD
                  [AXNR 4 ID S-0-0092 P=P2092
                                                TYP 2 DEC 0 SERC]
N070 #IDENT RD
                  [AXNR 4 ID S-0-0159 P=P2159 TYP 4 DEC 0 SERC]
; enable torque limiting
NO80 #IDENT WR SYN [AXNR 1 ID S-0-0092 VAL=100 TYP 2 DEC 0 SERC]
N090 #IDENT WR SYN [AXNR 4 ID S-0-0092 VAL=100 TYP 2 DEC 0 SERC]
; disable position lag monitoring in drives
N100 #IDENT WR SYN [AXNR 1 ID S-0-0159 VAL=0
                                             TYP 4 DEC 0 SERC]
N110 #IDENT WR SYN [AXNR 4 ID S-0-0159 VAL=0 TYP 4 DEC 0 SERC]
; start measurement run
N120 G100 X1000 Y1000 Z1000 Z2=1000 F1000
; move away from fixed stop
N130 G01 X100 F1000
; re-enable position lag monitoring
N140 #IDENT WR SYN [AXNR 1 ID S-0-0159 VAL=P1159 TYP 4 DEC 0 SERC]
N150 #IDENT WR SYN [AXNR 4 ID S-0-0159 VAL=P2159 TYP 4 DEC 0 SERC]
; disable torque limiting
N160 #IDENT WR SYN [AXNR 1 ID S-0-0092 VAL=P1092 TYP 2 DEC 0 SERC]
N170 #IDENT WR SYN [AXNR 4 ID S-0-0092 VAL=P2092 TYP 2 DEC 0 SERC]
N180 M30
