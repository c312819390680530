# Writes Praat's reference pitch and intensity of a sound, one row per frame.
#   praat --run praat_reference.praat IN.wav PITCH.csv INTENSITY.csv
# Pitch: To Pitch (ac) with Praat's standard settings except the 10 ms step
# (75-600 Hz, 15 candidates, not very accurate, silence 0.03, voicing 0.45,
# octave 0.01, octave-jump 0.35, voiced/unvoiced 0.14).
# Intensity: To Intensity, minimum pitch 75 Hz, 10 ms, mean subtracted.
# Multi-channel sounds are mixed to mono first (as kinemo does).
form Praat reference
  sentence Infile
  sentence Pitch_csv
  sentence Intensity_csv
endform
sound = Read from file: infile$
nch = Get number of channels
if nch > 1
  mono = Convert to mono
  removeObject: sound
  sound = mono
endif
selectObject: sound
pitch = To Pitch (ac): 0.01, 75, 15, "no", 0.03, 0.45, 0.01, 0.35, 0.14, 600
n = Get number of frames
out$ = "time_s,f0_hz" + newline$
for i to n
  t = Get time from frame number: i
  f = Get value in frame: i, "Hertz"
  if f = undefined
    f = 0
  endif
  out$ = out$ + fixed$(t, 6) + "," + fixed$(f, 4) + newline$
endfor
writeFile: pitch_csv$, out$
selectObject: sound
intensity = To Intensity: 75, 0.01, "yes"
n = Get number of frames
out$ = "time_s,intensity_db" + newline$
for i to n
  t = Get time from frame number: i
  v = Get value in frame: i
  if v = undefined
    v = -300
  endif
  out$ = out$ + fixed$(t, 6) + "," + fixed$(v, 4) + newline$
endfor
writeFile: intensity_csv$, out$
