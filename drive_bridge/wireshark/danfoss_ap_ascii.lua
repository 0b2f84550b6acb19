-- danfoss_ap_ascii: Wireshark dissector of AP ASCII, the MCD soft starters' serial protocol.
--
-- Shipped with drive_bridge (docs/wireshark.md). One frame a packet, as drive_bridge's wire
-- traces export them under the name "danfoss_ap_ascii"; the direction is frame.p2p_dir (0 =
-- sent by the master, the bridge; 1 = received from the starter), else told by the frame.
--
-- Frames as in drive_bridge/protocol/ap_ascii.py (MCD Modbus Module manual 000 section 10,
-- its second extraction 001, shared/research/protocols.md):
--   address fragment  EOT(04h) n n lrc lrc ENQ(05h)  master; LRC with or without EOT
--   message fragment  STX(02h) c c c lrc lrc ETX(03h) master: commands B10-B18 (10.1),
--                     requests C18 trip code, C22 status (10.2), D10 current, D12 temperature
--                     (10.3); LRC over STX and the code (10.4: STX B 1 0 -> 5Bh)
--   data reply        STX d d d d lrc lrc ETX, the starter's answer to C18/C22/D10/D12:
--                     status digits "00" + two nibbles in ASCII hex or 30h + nibble (001),
--                     data digits decimal 0000-9999
--   ACK 06h / NAK 15h (the starter saw a bad LRC) / BEL 07h (command refused)
-- LRC: two's complement of the byte sum, as two ASCII hex characters (10.4).
-- A reply names no unit and no request: the dissector takes both from the master's fragments
-- before it (on the first pass, in capture order).
-- Written for Wireshark 4.0 (Lua 5.2) and later (Lua 5.3/5.4): no bit operators.

local proto = Proto('danfoss_ap_ascii', 'Danfoss MCD AP ASCII')

local STX, ETX, EOT, ENQ, ACK, NAK, BEL = 0x02, 0x03, 0x04, 0x05, 0x06, 0x15, 0x07

local function bits(value, low, width)
    return math.floor(value / 2 ^ low) % 2 ^ (width or 1)
end

local DIRECTIONS = { [0] = 'master to starter', [1] = 'starter to master' }
local KINDS = {
    [1] = 'address fragment', [2] = 'command', [3] = 'request', [4] = 'data reply',
    [5] = 'ACK', [6] = 'NAK', [7] = 'BEL',
}
local KIND_ADDRESS, KIND_COMMAND, KIND_REQUEST, KIND_DATA = 1, 2, 3, 4
local SINGLE = { [ACK] = 5, [NAK] = 6, [BEL] = 7 }
local COMMANDS = {
    B10 = 'start', B12 = 'stop', B14 = 'reset', B16 = 'quick stop',
    B18 = 'forced communication trip',
}
local REQUESTS = {
    C18 = 'trip code', C22 = 'status', D10 = 'motor current', D12 = 'motor temperature',
}
-- C22 bits 0-3 (section 10.2).
local STATES = {
    [1] = 'ready', [2] = 'starting', [3] = 'running', [4] = 'stopping (including braking)',
    [5] = 'restart delay (including temperature check)', [6] = 'tripped', [7] = 'program mode',
    [8] = 'jog forward', [9] = 'jog reverse',
}
-- C18: the Modbus Module's trip codes (manual 000 section 7, drive_bridge/devices/mcd.py).
local TRIPS = {
    [1] = 'Excess start time', [2] = 'Motor overload (thermal model)', [3] = 'Motor thermistor',
    [4] = 'Current imbalance', [5] = 'Frequency (mains supply)', [6] = 'Phase sequence',
    [7] = 'Instantaneous overcurrent', [8] = 'Power loss (power circuit)', [9] = 'Undercurrent',
    [10] = 'Heatsink overtemperature', [11] = 'Motor connection',
    [12] = 'Input A trip (auxiliary input A)', [13] = 'FLC too high (FLC out of range)',
    [14] = 'Unsupported option (not available in 6-wire)', [15] = 'Starter communication',
    [16] = 'Network communication', [17] = 'Internal fault', [23] = 'EEPROM fail',
    [26] = 'L1 phase loss', [27] = 'L2 phase loss', [28] = 'L3 phase loss',
    [29] = 'L1-T1 shorted', [30] = 'L2-T2 shorted', [31] = 'L3-T3 shorted',
    [33] = 'Time-overcurrent (bypass overload)', [35] = 'Battery/clock',
    [36] = 'Thermistor circuit', [255] = 'no trip',
}
-- C18 of an MCD 3000 (protocols.md; drive_bridge/devices/mcd_ascii.py).
local MCD3000_TRIPS = {
    [0] = 'Shorted SCR', [1] = 'Excess start time', [2] = 'Overcurrent',
    [3] = 'Motor thermistor', [4] = 'Phase imbalance', [5] = 'Supply frequency',
    [6] = 'Phase rotation', [7] = 'Instantaneous overload', [8] = 'Power circuit',
    [9] = 'Undercurrent', [10] = 'Starter overtemperature', [255] = 'no trip',
}

local f = {
    direction = ProtoField.uint8('danfoss_ap_ascii.direction', 'Direction', base.DEC,
                                 DIRECTIONS),
    kind = ProtoField.uint8('danfoss_ap_ascii.kind', 'Frame type', base.DEC, KINDS),
    address = ProtoField.uint8('danfoss_ap_ascii.address', 'Address (unit)', base.DEC),
    code = ProtoField.string('danfoss_ap_ascii.code', 'Command/request code'),
    command = ProtoField.string('danfoss_ap_ascii.command', 'Command'),
    request = ProtoField.string('danfoss_ap_ascii.request', 'Request'),
    data = ProtoField.string('danfoss_ap_ascii.data', 'Data digits'),
    answers = ProtoField.string('danfoss_ap_ascii.answers', 'Answers code'),
    request_frame = ProtoField.framenum('danfoss_ap_ascii.request_frame', 'Request in frame'),
    status = ProtoField.uint8('danfoss_ap_ascii.status', 'Starter status (C22)', base.HEX),
    state = ProtoField.uint8('danfoss_ap_ascii.status.state', 'State', base.DEC, STATES, 0x0F),
    positive_rotation = ProtoField.bool('danfoss_ap_ascii.status.positive_rotation',
                                        'Positive phase rotation (valid if initialised)', 8,
                                        nil, 0x10),
    current_above_flc = ProtoField.bool('danfoss_ap_ascii.status.current_above_flc',
                                        'Current exceeds FLC', 8, nil, 0x20),
    initialised = ProtoField.bool('danfoss_ap_ascii.status.initialised', 'Initialised', 8,
                                  nil, 0x40),
    comms_fault = ProtoField.bool('danfoss_ap_ascii.status.comms_fault',
                                  'Communications device fault', 8, nil, 0x80),
    trip_code = ProtoField.uint8('danfoss_ap_ascii.trip_code', 'Trip code (C18)', base.DEC),
    trip_name = ProtoField.string('danfoss_ap_ascii.trip_name', 'Trip'),
    current_a = ProtoField.uint16('danfoss_ap_ascii.current_a', 'Motor current (A, D10)',
                                  base.DEC),
    temperature_pct = ProtoField.uint16('danfoss_ap_ascii.temperature_pct',
                                        'Motor temperature (% thermal capacity, D12)', base.DEC),
    lrc = ProtoField.string('danfoss_ap_ascii.lrc', 'LRC'),
    lrc_bad = ProtoField.bool('danfoss_ap_ascii.lrc_bad', 'LRC bad'),
    reply = ProtoField.uint8('danfoss_ap_ascii.reply', 'One-byte reply', base.HEX,
                             { [ACK] = 'ACK', [NAK] = 'NAK (bad LRC)', [BEL] = 'BEL (refused)' }),
    end_byte = ProtoField.uint8('danfoss_ap_ascii.end', 'End byte', base.HEX),
}
local all_fields = {}
for _, field in pairs(f) do
    table.insert(all_fields, field)
end
proto.fields = all_fields

local e = {
    bad_start = ProtoExpert.new('danfoss_ap_ascii.bad_start', 'Unknown start byte',
                                expert.group.MALFORMED, expert.severity.ERROR),
    bad_length = ProtoExpert.new('danfoss_ap_ascii.bad_length', 'Wrong length',
                                 expert.group.MALFORMED, expert.severity.ERROR),
    bad_end = ProtoExpert.new('danfoss_ap_ascii.bad_end', 'Wrong end byte',
                              expert.group.MALFORMED, expert.severity.ERROR),
    bad_lrc = ProtoExpert.new('danfoss_ap_ascii.bad_lrc', 'Bad LRC', expert.group.CHECKSUM,
                              expert.severity.ERROR),
    bad_digits = ProtoExpert.new('danfoss_ap_ascii.bad_digits', 'Digits not as the request',
                                 expert.group.MALFORMED, expert.severity.ERROR),
    nak = ProtoExpert.new('danfoss_ap_ascii.nak', 'NAK: the starter received a bad LRC',
                          expert.group.RESPONSE_CODE, expert.severity.ERROR),
    bel = ProtoExpert.new('danfoss_ap_ascii.bel', 'BEL: the starter refused the command',
                          expert.group.RESPONSE_CODE, expert.severity.WARN),
}
proto.experts = { e.bad_start, e.bad_length, e.bad_end, e.bad_lrc, e.bad_digits, e.nak,
                  e.bel }

local prefs = proto.prefs
prefs.mcd3000 = Pref.bool('MCD 3000 trip codes', false,
                          'Name C18 trip codes from the MCD 3000 table (else the MCD Modbus '
                          .. 'Module table: MCD 201/202/500)')

-- What the master said last, and what each frame answered (filled on the first pass).
local last = {}
local context = {}

function proto.init()
    last = {}
    context = {}
end

-- Text for the Info column and messages: printable ASCII kept, other bytes as \xNN.
local function printable(text)
    return (text:gsub('[^\32-\126]', function(char)
        return string.format('\\x%02X', char:byte())
    end))
end

local function byte_sum(tvb, offset, length)
    local sum = 0
    for _, byte in ipairs({ tvb:raw(offset, length):byte(1, -1) }) do
        sum = sum + byte
    end
    return sum
end

-- Whether the two LRC characters at lrc_offset make the body sum to 0 (or, when skip_first,
-- the body without its first byte: ap_ascii.lrc_matches).
local function lrc_ok(tvb, body_length, skip_first)
    local text = tvb(body_length, 2):string()
    local value = tonumber(text, 16)
    if value == nil or not text:match('^%x%x$') then
        return false
    end
    if (byte_sum(tvb, 0, body_length) + value) % 256 == 0 then
        return true
    end
    return skip_first and (byte_sum(tvb, 1, body_length - 1) + value) % 256 == 0
end

local function nibble(char)
    if char >= 0x30 and char <= 0x3F then
        return char - 0x30
    elseif char >= 0x41 and char <= 0x46 then
        return char - 0x41 + 10
    end
    return nil
end

-- The status byte of four status digits "00" + two nibbles, or nil.
local function status_value(digits)
    if digits:sub(1, 2) ~= '00' then
        return nil
    end
    local high, low = nibble(digits:byte(3)), nibble(digits:byte(4))
    if high == nil or low == nil then
        return nil
    end
    return high * 16 + low
end

local function add_lrc(tree, tvb, body_length, skip_first, parts)
    local range = tvb(body_length, 2)
    local item = tree:add(f.lrc, range)
    local good = lrc_ok(tvb, body_length, skip_first)
    item:add(f.lrc_bad, range, not good):set_generated()
    if good then
        item:append_text(' [correct]')
    else
        item:add_proto_expert_info(e.bad_lrc, string.format(
            'Bad LRC "%s": expected %02X', printable(range:string()),
            (256 - byte_sum(tvb, 0, body_length) % 256) % 256))
        table.insert(parts, '[BAD LRC]')
    end
end

local function add_end(tree, tvb, offset, expected, parts)
    local item = tree:add(f.end_byte, tvb(offset, 1))
    if tvb(offset, 1):uint() ~= expected then
        item:add_proto_expert_info(e.bad_end, string.format(
            'End byte %02Xh, expected %02Xh', tvb(offset, 1):uint(), expected))
        table.insert(parts, '[BAD END]')
    end
end

local function remember(pinfo, update)
    local seen = context[pinfo.number]
    if seen == nil then
        seen = { address = last.address, code = last.code, code_frame = last.code_frame,
                 kind = last.kind }
        context[pinfo.number] = seen
        update()
    end
    return seen
end

local function dissect_address(tvb, pinfo, tree, parts)
    local digits = printable(tvb(1, 2):string())
    local address = tonumber(digits)
    if address == nil or not digits:match('^%d%d$') then
        tree:add_proto_expert_info(e.bad_digits, 'Address digits "' .. digits
                                   .. '" are not two decimal digits')
        table.insert(parts, 'address fragment, bad digits')
    else
        tree:add(f.address, tvb(1, 2), address)
        table.insert(parts, string.format('unit %d: address fragment', address))
    end
    remember(pinfo, function()
        last = { address = address, kind = KIND_ADDRESS }
    end)
    add_lrc(tree, tvb, 3, true, parts)
    add_end(tree, tvb, 5, ENQ, parts)
end

local function dissect_message(tvb, pinfo, tree, parts)
    local code = printable(tvb(1, 3):string())
    local seen = remember(pinfo, function()
        last.code, last.code_frame = code, pinfo.number
        last.kind = REQUESTS[code] and KIND_REQUEST or KIND_COMMAND
    end)
    if seen.address ~= nil then
        tree:add(f.address, seen.address):set_generated()
    end
    local unit = seen.address and string.format('unit %d: ', seen.address) or ''
    tree:add(f.code, tvb(1, 3))
    if COMMANDS[code] then
        tree:add(f.kind, KIND_COMMAND):set_generated()
        tree:add(f.command, tvb(1, 3), COMMANDS[code])
        table.insert(parts, string.format('%scommand %s (%s)', unit, code, COMMANDS[code]))
    elseif REQUESTS[code] then
        tree:add(f.kind, KIND_REQUEST):set_generated()
        tree:add(f.request, tvb(1, 3), REQUESTS[code])
        table.insert(parts, string.format('%srequest %s (%s)', unit, code, REQUESTS[code]))
    else
        tree:add_proto_expert_info(e.bad_digits, 'Unknown command or request "' .. code .. '"')
        table.insert(parts, string.format('%sunknown code %s', unit, code))
    end
    add_lrc(tree, tvb, 4, false, parts)
    add_end(tree, tvb, 6, ETX, parts)
end

local function add_context(tree, seen)
    if seen.address ~= nil then
        tree:add(f.address, seen.address):set_generated()
    end
    if seen.code ~= nil then
        tree:add(f.answers, seen.code):set_generated()
        tree:add(f.request_frame, seen.code_frame):set_generated()
    end
    return seen.address and string.format('unit %d: ', seen.address) or ''
end

-- The four digits of a data reply, as the request before it asked (ap_ascii.decode_status,
-- decode_data).
local function decode_digits(tvb, tree, code, range)
    local digits = printable(range:string())
    if code == 'C22' or code == 'C18' then
        local value = status_value(digits)
        if value == nil then
            tree:add_proto_expert_info(e.bad_digits, 'Status digits "' .. digits
                                       .. '" are not 00 and two nibbles')
            return 'bad status digits ' .. digits
        end
        if code == 'C18' then
            local table_ = prefs.mcd3000 and MCD3000_TRIPS or TRIPS
            local name = table_[value] or 'unknown trip code'
            tree:add(f.trip_code, range, value)
            tree:add(f.trip_name, range, name):set_generated()
            return string.format('trip code %d (%s)', value, name)
        end
        local item = tree:add(f.status, range, value)
        for _, key in ipairs({ 'state', 'positive_rotation', 'current_above_flc',
                               'initialised', 'comms_fault' }) do
            item:add(f[key], range, value)
        end
        local state = STATES[bits(value, 0, 4)] or 'unknown state'
        item:append_text(' (' .. state .. ')')
        local text = string.format('status 0x%02X (%s)', value, state)
        if bits(value, 7) == 1 then
            text = text .. ', communications device fault'
        end
        return text
    end
    if not digits:match('^%d%d%d%d$') then
        tree:add_proto_expert_info(e.bad_digits, 'Data digits "' .. digits
                                   .. '" are not four decimal digits')
        return 'bad data digits ' .. digits
    end
    local value = tonumber(digits)
    if code == 'D10' then
        tree:add(f.current_a, range, value)
        return string.format('motor current %d A', value)
    elseif code == 'D12' then
        tree:add(f.temperature_pct, range, value)
        return string.format('motor temperature %d %%', value)
    end
    return 'data ' .. digits .. ' (no request seen)'
end

local function dissect_data(tvb, pinfo, tree, parts)
    local seen = remember(pinfo, function()
        last.kind = nil
    end)
    tree:add(f.kind, KIND_DATA):set_generated()
    local unit = add_context(tree, seen)
    local range = tvb(1, 4)
    tree:add(f.data, range)
    table.insert(parts, unit .. decode_digits(tvb, tree, seen.code, range))
    add_lrc(tree, tvb, 5, true, parts)
    add_end(tree, tvb, 7, ETX, parts)
end

local function dissect_single(tvb, pinfo, tree, parts, byte)
    local seen = remember(pinfo, function()
        if byte ~= ACK then
            last.kind = nil
        end
    end)
    tree:add(f.kind, SINGLE[byte]):set_generated()
    local unit = add_context(tree, seen)
    local item = tree:add(f.reply, tvb(0, 1))
    local what = ''
    if seen.kind == KIND_ADDRESS then
        what = ' to the address'
    elseif seen.kind == KIND_COMMAND or seen.kind == KIND_REQUEST then
        what = string.format(' to %s', seen.code)
    end
    if byte == NAK then
        item:add_proto_expert_info(e.nak)
        table.insert(parts, unit .. 'NAK' .. what .. ' (the starter saw a bad LRC)')
    elseif byte == BEL then
        item:add_proto_expert_info(e.bel)
        table.insert(parts, unit .. 'BEL' .. what .. ' (refused)')
    else
        table.insert(parts, unit .. 'ACK' .. what)
    end
end

-- By the first byte (and the length): the frame's length, its handler, its direction.
local function frame_spec(first, length)
    if first == EOT then
        return 6, dissect_address, 0
    elseif first == STX then
        if length <= 7 then
            return 7, dissect_message, 0
        end
        return 8, dissect_data, 1
    elseif SINGLE[first] then
        return 1, nil, 1
    end
    return nil, nil, nil
end

function proto.dissector(tvb, pinfo, tree)
    local length = tvb:len()
    pinfo.cols.protocol = 'AP ASCII'
    local root = tree:add(proto, tvb())
    if length == 0 then
        root:add_proto_expert_info(e.bad_length, 'Empty packet: no frame')
        pinfo.cols.info = 'Empty packet [WRONG LENGTH]'
        return 0
    end
    local first = tvb(0, 1):uint()
    local expected, handler, implied = frame_spec(first, length)
    local direction = pinfo.p2p_dir
    if direction ~= 0 and direction ~= 1 then
        direction = implied
    end
    if direction ~= nil then
        root:add(f.direction, direction):set_generated()
    end
    local parts = { direction == 0 and 'Master' or (direction == 1 and 'Starter' or '?') }
    if expected == nil then
        root:add_proto_expert_info(e.bad_start, string.format(
            'Unknown start byte %02Xh (not EOT, STX, ACK, NAK or BEL)', first))
        table.insert(parts, string.format('unknown start byte %02Xh', first))
        pinfo.cols.info = table.concat(parts, ' ')
        return length
    end
    if first == EOT then
        root:add(f.kind, KIND_ADDRESS):set_generated()
    end
    if length ~= expected then
        root:add_proto_expert_info(e.bad_length, string.format(
            'Wrong length: %d bytes, a %s has %d', length,
            first == EOT and 'address fragment' or (expected == 1 and 'one-byte reply'
                                                     or 'frame'), expected))
        if length < expected then
            table.insert(parts, string.format('frame cut (%d of %d bytes) [WRONG LENGTH]',
                                              length, expected))
            pinfo.cols.info = table.concat(parts, ' ')
            return length
        end
        table.insert(parts, '[WRONG LENGTH]')
    end
    if handler == nil then
        dissect_single(tvb, pinfo, root, parts, first)
    else
        handler(tvb, pinfo, root, parts)
    end
    -- the length error goes last in the Info column
    if parts[2] == '[WRONG LENGTH]' then
        table.insert(parts, table.remove(parts, 2))
    end
    pinfo.cols.info = table.concat(parts, ' ')
    return length
end
