-- danfoss_fc: Wireshark dissector of the Danfoss FC protocol (one telegram a packet).
--
-- Shipped with drive_bridge (docs/wireshark.md). Frames come from drive_bridge's wire traces
-- as exported PDUs naming "danfoss_fc"; the direction is frame.p2p_dir (0 = sent by the
-- master, the bridge: a request; 1 = received: the drive's reply).
--
-- Layout and bits as in drive_bridge/protocol/fc_telegram.py and fc_profile.py:
--   telegram  STX(02h) LGE ADR data BCC; LGE = the bytes after LGE (VLT 5000 / FC 300 Design
--             Guides "Telegram Structure"); LGE 6 process block (PCD1 PCD2), 14 parameter block
--             (PKE IND PWEhigh PWElow PCD1 PCD2), 10 + n text block (manual 003 "Text Blocks")
--   BCC       XOR of every byte from STX up to BCC (worked example 02 D6 -> D4)
--   ADR       bit 7 set: format 1-126, bits 0-6 the address (0 = broadcast); bit 7 clear:
--             format 1-31, bit 5 = broadcast, bits 0-4 the address
--   PKE       AK (bits 12-15) << 12 | PNU (bits 0-11; VLT 5000/6000 bits 0-10)
--   CTW       FC 51 manual (004) 5.6.1 "Control Word According to FC Profile"; VLT 5000/6000
--             manual (003) "FC Protocol Control Word Bit Descriptions" (bit 12 relay 2,
--             bits 13-14 set-up)
--   STW       manual 004 5.6.3 "Status Word According to FC Profile (STW)"
--   REF, MAV  manual 004 5.6.5 "Bus Speed Reference Value": 4000h = 100 %, signed
-- Written for Wireshark 4.0 (Lua 5.2) and later (Lua 5.3/5.4): no bit operators.

local proto = Proto('danfoss_fc', 'Danfoss FC protocol')

local STX = 0x02
local LGE_PROCESS, LGE_PARAMETER, LGE_TEXT_FIXED = 6, 14, 10

local function bits(value, low, width)
    return math.floor(value / 2 ^ low) % 2 ^ (width or 1)
end

local function xor2(a, b)
    local result, bit = 0, 1
    while a > 0 or b > 0 do
        if a % 2 ~= b % 2 then
            result = result + bit
        end
        a, b, bit = math.floor(a / 2), math.floor(b / 2), bit * 2
    end
    return result
end

-- Lua 5.2 (Wireshark 4.0) has bit32; without it (Lua 5.3+ built without compatibility) xor2.
local bxor = bit32 and bit32.bxor or xor2

local function xor_bytes(tvb, offset, length)
    local result = 0
    for _, byte in ipairs({ tvb:raw(offset, length):byte(1, -1) }) do
        result = bxor(result, byte)
    end
    return result
end

-- Text for the Info column: printable ASCII kept, other bytes as \xNN.
local function printable(text)
    return (text:gsub('[^\32-\126]', function(char)
        return string.format('\\x%02X', char:byte())
    end))
end

local function signed16(word)
    return word >= 0x8000 and word - 0x10000 or word
end

local function percent(word)
    return signed16(word) * 100.0 / 0x4000
end

local DIRECTIONS = { [0] = 'request (master to drive)', [1] = 'reply (drive to master)' }
local TELEGRAM_TYPES = { [1] = 'process block (PCD)', [2] = 'parameter block (PKE IND PWE)',
                         [3] = 'text block' }
local SHORT_TYPES = { [1] = 'process', [2] = 'parameter', [3] = 'text' }
local REQUEST_AKS = {
    [0] = 'no command', [1] = 'read', [2] = 'write word (RAM)',
    [3] = 'write double word (RAM)', [13] = 'write double word (RAM and EEPROM)',
    [14] = 'write word (RAM and EEPROM)', [15] = 'read/write text',
}
local REPLY_AKS = {
    [0] = 'no response', [1] = 'value (word)', [2] = 'value (double word)',
    [7] = 'cannot be performed', [15] = 'text',
}
-- AK 7 error codes (PWElow): fc_telegram.ERROR_CODES (VLT 6000 HVAC Design Guide MG.60.B1.02,
-- FC 300 MG.33.B3.22, FC 101 MG18C522 table 7.7, FC 51 MG02K202 table 8.7, FCP 106 table 3.7).
local ERROR_CODES = {
    [0] = 'the parameter number does not exist',
    [1] = 'the parameter cannot be changed (no write access)',
    [2] = 'the value is outside the parameter limits',
    [3] = 'the sub-index (IND) does not exist',
    [4] = 'the parameter is not an array',
    [5] = 'the data type does not match the parameter (word/double word/text)',
    [9] = 'the description element is not available',
    [11] = 'no parameter write access',
    [15] = 'no text available',
    [17] = 'not possible while running: stop the motor first',
    [18] = 'other error',
    [23] = 'the parameter database is busy',
    [130] = 'no bus access to this parameter',
    [131] = 'write to the factory set-up is not possible',
    [132] = 'no LCP access',
    [252] = 'unknown viewer',
    [253] = 'request not supported',
    [254] = 'unknown attribute',
    [255] = 'no error',
}

local f = {
    direction = ProtoField.uint8('danfoss_fc.direction', 'Direction', base.DEC, DIRECTIONS),
    stx = ProtoField.uint8('danfoss_fc.stx', 'Start byte (STX)', base.HEX),
    lge = ProtoField.uint8('danfoss_fc.lge', 'Length (LGE)', base.DEC),
    telegram_type = ProtoField.uint8('danfoss_fc.telegram_type', 'Telegram type', base.DEC,
                                     TELEGRAM_TYPES),
    adr = ProtoField.uint8('danfoss_fc.adr', 'Address byte (ADR)', base.HEX),
    address = ProtoField.uint8('danfoss_fc.address', 'Address', base.DEC),
    address_format = ProtoField.string('danfoss_fc.address_format', 'Address format'),
    broadcast = ProtoField.bool('danfoss_fc.broadcast', 'Broadcast'),
    pke = ProtoField.uint16('danfoss_fc.pke', 'Parameter key (PKE)', base.HEX),
    ak = ProtoField.uint16('danfoss_fc.ak', 'AK (parameter command/reply)', base.DEC, nil,
                           0xF000),
    ak_name = ProtoField.string('danfoss_fc.ak_name', 'AK meaning'),
    pnu = ProtoField.uint16('danfoss_fc.pnu', 'Parameter number (PNU)', base.DEC, nil, 0x0FFF),
    ind = ProtoField.uint16('danfoss_fc.ind', 'Index (IND)', base.HEX),
    pwe = ProtoField.uint32('danfoss_fc.pwe', 'Parameter value (PWE)', base.DEC_HEX),
    error_code = ProtoField.uint16('danfoss_fc.error_code', 'Error code (AK 7, PWElow)',
                                   base.DEC, ERROR_CODES),
    text = ProtoField.string('danfoss_fc.text', 'Text'),
    pcd1 = ProtoField.uint16('danfoss_fc.pcd1', 'PCD1', base.HEX),
    pcd2 = ProtoField.uint16('danfoss_fc.pcd2', 'PCD2', base.HEX),
    ctw = ProtoField.uint16('danfoss_fc.ctw', 'Control word (CTW)', base.HEX),
    ctw_summary = ProtoField.string('danfoss_fc.ctw_summary', 'Control word says'),
    ref = ProtoField.uint16('danfoss_fc.ref', 'Bus reference (REF)', base.HEX),
    ref_percent = ProtoField.double('danfoss_fc.ref_percent', 'Bus reference (%)'),
    stw = ProtoField.uint16('danfoss_fc.stw', 'Status word (STW)', base.HEX),
    stw_summary = ProtoField.string('danfoss_fc.stw_summary', 'Status word says'),
    mav = ProtoField.uint16('danfoss_fc.mav', 'Main actual value (MAV)', base.HEX),
    mav_percent = ProtoField.double('danfoss_fc.mav_percent', 'Main actual value (%)'),
    bcc = ProtoField.uint8('danfoss_fc.bcc', 'Checksum (BCC)', base.HEX),
    bcc_bad = ProtoField.bool('danfoss_fc.bcc_bad', 'BCC bad'),
    extra = ProtoField.bytes('danfoss_fc.extra', 'Bytes after the telegram'),
}

-- Control word bits: {key, name, mask, text when 1, text when 0}.
local CTW_BITS = {
    { 'preset_ref', 'Preset reference select', 0x0003 },
    { 'dc_brake_off', 'Bit 2, DC brake', 0x0004, 'ramp (no DC brake)', 'DC brake' },
    { 'coast_off', 'Bit 3, coasting', 0x0008, 'no coasting', 'coast stop' },
    { 'quick_stop_off', 'Bit 4, quick stop', 0x0010, 'ramp (no quick stop)', 'quick stop' },
    { 'no_freeze', 'Bit 5, freeze output', 0x0020, 'no freeze output', 'freeze output' },
    { 'start', 'Bit 6, start/ramp stop', 0x0040, 'start', 'ramp stop' },
    { 'reset', 'Bit 7, reset', 0x0080, 'reset', 'no reset' },
    { 'jog', 'Bit 8, jog', 0x0100, 'jog', 'no jog' },
    { 'ramp_2', 'Bit 9, ramp select', 0x0200, 'ramp 2', 'ramp 1' },
    { 'data_valid', 'Bit 10, data valid', 0x0400, 'data valid', 'data not valid (CTW ignored)' },
    { 'relay_1', 'Bit 11, relay 1', 0x0800, 'relay 1 on', 'relay 1 off' },
    { 'relay_2', 'Bit 12, relay 2 (VLT 5000/6000)', 0x1000, 'relay 2 on', 'relay 2 off' },
    { 'setup', 'Set-up select (FC 51: bit 13; VLT: bits 13-14)', 0x6000 },
    { 'reverse', 'Bit 15, reversing', 0x8000, 'reverse', 'no reversing' },
}
-- Status word bits (manual 004 5.6.3).
local STW_BITS = {
    { 'control_ready', 'Bit 0, control ready', 0x0001, 'control ready', 'control not ready' },
    { 'unit_ready', 'Bit 1, unit ready', 0x0002, 'unit ready', 'unit not ready' },
    { 'enabled', 'Bit 2, enable/coasting', 0x0004, 'enable', 'coasting' },
    { 'trip', 'Bit 3, trip', 0x0008, 'error, trip', 'no error' },
    { 'error_no_trip', 'Bit 4, error without trip', 0x0010, 'error (no trip)', 'no error' },
    { 'trip_locked', 'Bit 6, trip locked', 0x0040, 'trip locked', 'not trip locked' },
    { 'warning', 'Bit 7, warning', 0x0080, 'warning', 'no warning' },
    { 'on_reference', 'Bit 8, on reference', 0x0100, 'speed = reference', 'speed <> reference' },
    { 'bus_control', 'Bit 9, bus control', 0x0200,
       'bus control', 'local operation (CTW ignored)' },
    { 'frequency_ok', 'Bit 10, frequency limit', 0x0400,
       'frequency limit OK', 'out of frequency limit' },
    { 'running', 'Bit 11, running', 0x0800, 'running', 'not running' },
    { 'brake_fault', 'Bit 12, resistor brake', 0x1000,
       'resistor brake fault', 'no resistor brake fault' },
    { 'voltage_exceeded', 'Bit 13, voltage', 0x2000, 'voltage exceeded', 'voltage OK' },
    { 'torque_exceeded', 'Bit 14, torque', 0x4000, 'torque exceeded', 'torque OK' },
    { 'thermal_warning', 'Bit 15, thermal', 0x8000, 'thermal warning', 'no thermal warning' },
}

local function bit_fields(prefix, table_)
    local fields = {}
    for _, spec in ipairs(table_) do
        local key, name, mask, on, off = spec[1], spec[2], spec[3], spec[4], spec[5]
        local abbr = prefix .. '.' .. key
        if on then
            fields[key] = ProtoField.bool(abbr, name, 16, { on, off }, mask)
        else
            fields[key] = ProtoField.uint16(abbr, name, base.DEC, nil, mask)
        end
    end
    return fields
end

local ctw_fields = bit_fields('danfoss_fc.ctw', CTW_BITS)
local stw_fields = bit_fields('danfoss_fc.stw', STW_BITS)

local all_fields = {}
for _, field in pairs(f) do
    table.insert(all_fields, field)
end
for _, field in pairs(ctw_fields) do
    table.insert(all_fields, field)
end
for _, field in pairs(stw_fields) do
    table.insert(all_fields, field)
end
proto.fields = all_fields

local e = {
    bad_stx = ProtoExpert.new('danfoss_fc.bad_stx', 'Unknown start byte (not STX 02h)',
                              expert.group.MALFORMED, expert.severity.ERROR),
    bad_length = ProtoExpert.new('danfoss_fc.bad_length', 'Wrong length',
                                 expert.group.MALFORMED, expert.severity.ERROR),
    bad_bcc = ProtoExpert.new('danfoss_fc.bad_bcc', 'Bad BCC', expert.group.CHECKSUM,
                              expert.severity.ERROR),
    ak_error = ProtoExpert.new('danfoss_fc.ak_error', 'Parameter command cannot be performed',
                               expert.group.RESPONSE_CODE, expert.severity.WARN),
}
proto.experts = { e.bad_stx, e.bad_length, e.bad_bcc, e.ak_error }

-- What a control word asks for, in words (stop precedence: coast, quick stop, DC brake,
-- ramp; manual 003 "Stop Commands").
local function ctw_summary(word)
    local words
    if bits(word, 10) == 0 then
        words = 'data not valid'
    elseif bits(word, 3) == 0 then
        words = 'coast stop'
    elseif bits(word, 4) == 0 then
        words = 'quick stop'
    elseif bits(word, 2) == 0 then
        words = 'DC brake'
    elseif bits(word, 6) == 0 then
        words = 'ramp stop'
    else
        words = 'run'
    end
    if bits(word, 10) == 1 then
        if bits(word, 5) == 0 then words = words .. ', freeze' end
        if bits(word, 7) == 1 then words = words .. ', reset' end
        if bits(word, 8) == 1 then words = words .. ', jog' end
        if bits(word, 15) == 1 then words = words .. ', reverse' end
    end
    return words
end

local function stw_summary(word)
    local words
    if bits(word, 3) == 1 or bits(word, 6) == 1 then
        words = bits(word, 6) == 1 and 'trip locked' or 'tripped'
    elseif bits(word, 0) == 0 or bits(word, 1) == 0 then
        words = 'not ready'
    elseif bits(word, 11) == 1 then
        words = bits(word, 8) == 1 and 'running, on reference' or 'running'
    else
        words = 'ready'
    end
    if bits(word, 7) == 1 then words = words .. ', warning' end
    if bits(word, 9) == 0 then words = words .. ', local operation' end
    return words
end

local function add_word(tree, tvb, offset, field, summary_field, summary, bit_table, fields)
    local range = tvb(offset, 2)
    local word = range:uint()
    local item = tree:add(field, range)
    item:append_text(' (' .. summary(word) .. ')')
    item:add(summary_field, range, summary(word)):set_generated()
    for _, spec in ipairs(bit_table) do
        item:add(fields[spec[1]], range)
    end
    return word
end

local function add_pcd(tree, tvb, offset, direction)
    local info
    if direction == 0 then
        local ctw = add_word(tree, tvb, offset, f.ctw, f.ctw_summary, ctw_summary, CTW_BITS,
                             ctw_fields)
        local ref = tvb(offset + 2, 2):uint()
        tree:add(f.ref, tvb(offset + 2, 2))
        tree:add(f.ref_percent, tvb(offset + 2, 2), percent(ref)):set_generated()
        info = string.format('CTW 0x%04X (%s) REF %.1f %%', ctw, ctw_summary(ctw), percent(ref))
    elseif direction == 1 then
        local stw = add_word(tree, tvb, offset, f.stw, f.stw_summary, stw_summary, STW_BITS,
                             stw_fields)
        local mav = tvb(offset + 2, 2):uint()
        tree:add(f.mav, tvb(offset + 2, 2))
        tree:add(f.mav_percent, tvb(offset + 2, 2), percent(mav)):set_generated()
        info = string.format('STW 0x%04X (%s) MAV %.1f %%', stw, stw_summary(stw), percent(mav))
    else
        tree:add(f.pcd1, tvb(offset, 2))
        tree:add(f.pcd2, tvb(offset + 2, 2))
        info = string.format('PCD1 0x%04X PCD2 0x%04X', tvb(offset, 2):uint(),
                             tvb(offset + 2, 2):uint())
    end
    return info
end

local function add_address(tree, tvb)
    local adr = tvb(2, 1):uint()
    local item = tree:add(f.adr, tvb(2, 1))
    local address, format, broadcast
    if bits(adr, 7) == 1 then
        address, format = bits(adr, 0, 7), '1-126'
        broadcast = address == 0
    elseif bits(adr, 5) == 1 then
        address, format, broadcast = 0, '1-31', true
    else
        address, format = bits(adr, 0, 5), '1-31'
        broadcast = address == 0
    end
    item:add(f.address, tvb(2, 1), address):set_generated()
    item:add(f.address_format, tvb(2, 1), format):set_generated()
    item:add(f.broadcast, tvb(2, 1), broadcast):set_generated()
    item:append_text(string.format(' (address %d, format %s%s)', address, format,
                                   broadcast and ', broadcast' or ''))
    return broadcast and 'broadcast' or string.format('ADR %d', address)
end

-- The parameter channel (PKE IND PWE or text); returns the Info text.
local function add_parameter(tree, tvb, lge, direction)
    local pke = tvb(3, 2):uint()
    local ak, pnu = bits(pke, 12, 4), bits(pke, 0, 12)
    local names = direction == 1 and REPLY_AKS or (direction == 0 and REQUEST_AKS or {})
    local pke_item = tree:add(f.pke, tvb(3, 2))
    local ak_item = pke_item:add(f.ak, tvb(3, 2))
    local ak_name = names[ak] or (direction ~= nil and 'unknown' or 'direction unknown')
    ak_item:append_text(' (' .. ak_name .. ')')
    pke_item:add(f.ak_name, tvb(3, 2), ak_name):set_generated()
    pke_item:add(f.pnu, tvb(3, 2))
    tree:add(f.ind, tvb(5, 2))
    local info = string.format('AK %d %s PNU %d IND 0x%04X', ak, ak_name, pnu, tvb(5, 2):uint())
    if lge == LGE_PARAMETER then
        local pwe = tvb(7, 4):uint()
        tree:add(f.pwe, tvb(7, 4))
        if direction == 1 and ak == 7 then
            local code = tvb(9, 2):uint()
            local item = tree:add(f.error_code, tvb(9, 2))
            local text = ERROR_CODES[code] or 'error code not in the Danfoss tables'
            item:add_proto_expert_info(e.ak_error, string.format(
                'Parameter %d: cannot be performed, error %d: %s', pnu, code, text))
            info = info .. string.format(' error %d (%s)', code, text)
        else
            info = info .. string.format(' PWE %d', pwe)
        end
    else
        local length = lge - LGE_TEXT_FIXED
        if length > 0 then
            local text = tvb(7, length):string()
            tree:add(f.text, tvb(7, length))
            info = info .. string.format(' text "%s"', printable(text))
        else
            tree:add(f.text, tvb(7, 0), '')
            info = info .. ' text ""'
        end
    end
    return info
end

local function telegram_type(lge)
    if lge == LGE_PROCESS then
        return 1
    elseif lge == LGE_PARAMETER then
        return 2
    end
    return 3
end

function proto.dissector(tvb, pinfo, tree)
    local length = tvb:len()
    pinfo.cols.protocol = 'Danfoss FC'
    local root = tree:add(proto, tvb())
    if length == 0 then
        root:add_proto_expert_info(e.bad_length, 'Empty packet: no telegram')
        pinfo.cols.info = 'Empty packet [WRONG LENGTH]'
        return 0
    end
    local direction = pinfo.p2p_dir
    if direction ~= 0 and direction ~= 1 then
        direction = nil
    else
        root:add(f.direction, direction):set_generated()
    end
    local prefix = direction == 0 and 'Request' or (direction == 1 and 'Reply' or 'Telegram')
    local stx_item = root:add(f.stx, tvb(0, 1))
    if tvb(0, 1):uint() ~= STX then
        stx_item:add_proto_expert_info(e.bad_stx, string.format(
            'Unknown start byte %02Xh: an FC telegram starts with STX 02h', tvb(0, 1):uint()))
        pinfo.cols.info = string.format('%s: unknown start byte %02Xh', prefix,
                                        tvb(0, 1):uint())
        return length
    end
    if length < 2 then
        root:add_proto_expert_info(e.bad_length, 'Telegram cut after STX')
        pinfo.cols.info = prefix .. ': telegram cut after STX'
        return length
    end
    local lge = tvb(1, 1):uint()
    local lge_item = root:add(f.lge, tvb(1, 1))
    if lge ~= LGE_PROCESS and lge < LGE_TEXT_FIXED then
        lge_item:add_proto_expert_info(e.bad_length, string.format(
            'LGE %d is not 6, 14 or 10 + text length', lge))
        pinfo.cols.info = string.format('%s: wrong length, LGE %d', prefix, lge)
        return length
    end
    if length < lge + 2 then
        lge_item:add_proto_expert_info(e.bad_length, string.format(
            'Telegram cut: LGE %d needs %d bytes, the packet has %d', lge, lge + 2, length))
        pinfo.cols.info = string.format('%s: telegram cut (%d of %d bytes)', prefix, length,
                                        lge + 2)
        return length
    end
    local kind = telegram_type(lge)
    root:add(f.telegram_type, tvb(1, 1), kind):set_generated()
    local unit = add_address(root, tvb)
    local parts = { string.format('%s %s %s:', prefix, unit, SHORT_TYPES[kind]) }
    if kind ~= 1 then
        table.insert(parts, add_parameter(root, tvb, lge, direction))
    end
    table.insert(parts, add_pcd(root, tvb, lge - 3, direction))
    local bcc_range = tvb(lge + 1, 1)
    local bcc_item = root:add(f.bcc, bcc_range)
    local bad = xor_bytes(tvb, 0, lge + 2) ~= 0
    bcc_item:add(f.bcc_bad, bcc_range, bad):set_generated()
    if bad then
        local expected = xor_bytes(tvb, 0, lge + 1)
        bcc_item:append_text(string.format(' [bad: expected 0x%02X]', expected))
        bcc_item:add_proto_expert_info(e.bad_bcc, string.format(
            'Bad BCC 0x%02X: expected 0x%02X', bcc_range:uint(), expected))
        table.insert(parts, '[BAD BCC]')
    else
        bcc_item:append_text(' [correct]')
    end
    if length > lge + 2 then
        local extra = root:add(f.extra, tvb(lge + 2))
        extra:add_proto_expert_info(e.bad_length, string.format(
            'Wrong length: %d bytes after the telegram (LGE %d)', length - lge - 2, lge))
        table.insert(parts, '[WRONG LENGTH]')
    end
    root:append_text(string.format(', %s, %s', unit, TELEGRAM_TYPES[kind]))
    pinfo.cols.info = table.concat(parts, ' ')
    return length
end
