function twin_client (port, api)
  % TWIN_CLIENT  Drive the humanoid twin's serial port from GNU Octave, as the 2006 toolbox did.
  %
  %   humanoid-twin serve                     # prints the port, e.g. /dev/pts/3
  %   octave-cli --eval "addpath('examples/octave'); twin_client('/dev/pts/3')"
  %   octave-cli --eval "addpath('examples/octave'); twin_client('/dev/pts/3', 'serial')"
  %
  % api: 'serialport' (default; the serialport object, read / write) or 'serial' (the older
  % serial object with fopen / fwrite / fread / fclose). Needs Octave's instrument-control
  % package (Debian, Ubuntu: apt install octave octave-instrument-control).
  %
  % It opens the port at 115200 baud, 8 data bits, even parity, 1 stop bit (seed 002 slide 7),
  % then, with the 6-byte frames of docs/protocol.md:
  %   the test message    (calibcom, seed 000 table 20)   FF C0 00 00 00 3F -> FA F9 F8 F7 F6 F5
  %   PWM on, SCU 1       (applyjoint(H,1,3,[1 0 0]))     FF 07 01 00 00 F9 -> FB echo
  %   joint positions     (readjoint(H,1,0))              FF 84 00 00 00 7B -> FD p1 p2 p3 status
  %   the supervisor      (docs/supervisor.md)            FF C2 00 00 00 3D -> FD mode fault node n
  % and prints one line for each. Any wrong answer is an error (exit status 1 under octave-cli).
  %
  % Only the port name differs from a real COM port, with one thing to know on Linux: a pty
  % keeps no parity bit, and the C library of Debian and Ubuntu refuses (EINVAL) a settings
  % call that changes nothing else. So the port is opened first and its parity set
  % afterwards, in its own call (docs/serve.md, "Driving the twin from Octave or MATLAB").

  if nargin < 2
    api = 'serialport';
  end
  if exist ('OCTAVE_VERSION', 'builtin')
    pkg load instrument-control
  end

  H = initcom (port, 115200, api);
  fprintf ('%s (%s API): %d baud, %d data bits, parity %s, %d stop bit\n', port, api, ...
          H.baudrate, H.databits, H.parity, H.stopbits);

  rx = calibcom (H);
  fprintf ('test message: %s\n', hexbytes (rx));

  rx = applyjoint (H, 1, 3, [1 0 0]);
  fprintf ('PWM on, SCU 1: %s\n', hexbytes (rx));

  [servos, status, rx] = readjoint (H, 1, 0);
  fprintf ('joint positions, SCU 1: %s -> [%d %d %d] degrees, status 0x%02X\n', ...
          hexbytes (rx), servos, status);

  [mode, fault, node, nfaults, rx] = readsupervisor (H);
  fprintf ('supervisor: %s -> mode %s, first fault %d on node %d, %d fault(s) latched\n', ...
          hexbytes (rx), mode, fault, node, nfaults);

  killcom (H);
end


% -- the toolbox's device drivers (seed 000 table 20), on the serial object ---------------------

function H = initcom (port, rate, api)
  % Open the line at RATE 8E1. The parity is set after the rest, in its own call: see
  % set_even_parity.
  H.api = api;
  H.port = port;
  if strcmp (api, 'serialport')
    H.s = serialport (port, 'BaudRate', rate, 'DataBits', 8, 'StopBits', 1, 'Timeout', 1);
    set_even_parity (H, 'Parity');
    H.baudrate = get (H.s, 'BaudRate');
    H.databits = get (H.s, 'DataBits');
    H.stopbits = get (H.s, 'StopBits');
    H.parity = lower (get (H.s, 'Parity'));
  elseif strcmp (api, 'serial')
    H.s = serial (port, rate, 10);          % timeout 10 tenths of a second
    set (H.s, 'bytesize', 8);
    set (H.s, 'stopbits', 1);
    set_even_parity (H, 'parity');
    fopen (H.s);                            % Octave's serial is open already; MATLAB's needs it
    H.baudrate = get (H.s, 'baudrate');
    H.databits = get (H.s, 'bytesize');
    H.stopbits = get (H.s, 'stopbits');
    H.parity = lower (get (H.s, 'parity'));
  else
    error ('twin_client: api must be ''serialport'' or ''serial'', not ''%s''', api);
  end
end

function set_even_parity (H, property)
  % Set even parity. On a Linux pty the C library can answer EINVAL for a call whose only
  % effect would have been the parity bit (the pty keeps none); humanoid-twin serve marks the
  % pty again a few milliseconds after each settings change, so the same call made again
  % shortly after is accepted. A real port accepts it the first time.
  pty = strncmp (H.port, '/dev/pts/', 9);
  if pty
    pause (0.03);     % let serve mark the pty after the settings just made: usually one call
  end
  for attempt = 1:50
    try
      set (H.s, property, 'even');
      return;
    catch err
      if ~(pty && ~isempty (strfind (err.message, 'Invalid argument')))
        rethrow (err);
      end
      pause (0.02);
    end
  end
  error ('twin_client: the pty %s refused even parity for 1 s: is it served by humanoid-twin serve?', ...
         H.port);
end

function killcom (H)
  % The old serial object is closed by fclose; a serialport object when it is cleared (here,
  % when twin_client returns).
  if strcmp (H.api, 'serial')
    fclose (H.s);
  end
end

function rx = exchange (H, frame)
  % Send one 6-byte request, return the 6-byte answer (error if fewer arrive within the timeout).
  if strcmp (H.api, 'serialport')
    write (H.s, frame);
    rx = read (H.s, 6);
  else
    fwrite (H.s, frame);
    rx = fread (H.s, 6);
  end
  rx = uint8 (rx(:)');
  if numel (rx) ~= 6
    error ('twin_client: request %s: %d byte(s) in answer, expected 6', hexbytes (frame), numel (rx));
  end
end

function rx = calibcom (H)
  rx = exchange (H, request (3, 0, 0, [0 0 0]));
  if ~isequal (rx, uint8 ([250 249 248 247 246 245]))
    error ('twin_client: test message expected FA F9 F8 F7 F6 F5, got %s', hexbytes (rx));
  end
end

function rx = applyjoint (H, scu, param, servos)
  frame = request (0, scu, param, servos);
  rx = exchange (H, frame);
  check_answer (rx, 251, frame);
  if ~isequal (rx(2:5), frame(2:5))
    error ('twin_client: %s is not the echo of %s', hexbytes (rx), hexbytes (frame));
  end
end

function [servos, status, rx] = readjoint (H, scu, param)
  frame = request (2, scu, param, [0 0 0]);
  rx = exchange (H, frame);
  check_answer (rx, 253, frame);
  servos = double (typecast (rx(2:4), 'int8'));     % int8 degrees (docs/protocol.md 1.2)
  status = double (rx(5));
end

function [mode, fault, node, nfaults, rx] = readsupervisor (H)
  frame = request (3, 0, 2, [0 0 0]);
  rx = exchange (H, frame);
  check_answer (rx, 253, frame);
  modes = {'standby', 'self_check', 'ready', 'safe', 'estop'};
  if rx(2) < numel (modes)
    mode = modes{double (rx(2)) + 1};
  else
    mode = sprintf ('%d', rx(2));
  end
  fault = double (rx(3));
  node = double (rx(4));
  nfaults = double (rx(5));
end


% -- frames (docs/protocol.md section 1) --------------------------------------------------------

function frame = request (op, scu, param, data)
  % FF OP D1 D2 D3 BCC; OP = operation (bits 7-6), SCU (5-2), parameter (1-0); BCC = XOR of the 5.
  opcode = bitor (bitor (bitshift (op, 6), bitshift (scu, 2)), param);
  frame = uint8 ([255, opcode, mod(data(:)', 256), 0]);
  frame(6) = bcc (frame(1:5));
end

function b = bcc (bytes)
  b = uint8 (0);
  for k = 1:numel (bytes)
    b = bitxor (b, uint8 (bytes(k)));
  end
end

function check_answer (rx, first, frame)
  if rx(1) ~= first || bcc (rx(1:5)) ~= rx(6)
    error ('twin_client: request %s answered %s (expected %02X ... with a good BCC)', ...
           hexbytes (frame), hexbytes (rx), first);
  end
end

function text = hexbytes (bytes)
  text = strtrim (sprintf ('%02X ', bytes));
end
