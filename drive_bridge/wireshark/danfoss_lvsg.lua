-- danfoss_lvsg: Wireshark postdissector of the LVSG process image of MCD 200 starters with
-- the Profibus Module, as a DP-master gateway maps it to Modbus holding registers.
--
-- Shipped with drive_bridge (docs/wireshark.md). It runs after Wireshark's own Modbus RTU
-- and Modbus TCP dissectors, on every frame they decode, and adds the image's bytes and bits
-- to Modbus frames that read or write the registers of a slave named in the preference
-- "danfoss_lvsg.slaves" (nothing is added while it is empty):
--   unit:input_register:output_register[:module[:byte_order]], ...
--   e.g. "1:0:100:extended:big, 1:10:110:basic"  (module basic | extended, default extended;
--   byte order big = image byte 0 is a register's high byte (default) | little)
-- as the device's settings in drive_bridge (gateway_input_register, gateway_output_register,
-- lvsg_module, gateway_byte_order; docs/lvsg.md). Register numbers are frame addresses.
-- Requests and replies are told apart by frame.p2p_dir (0 = sent by the master), else by the
-- TCP port 502; a read reply is matched to the last read request of its unit before it.
--
-- Bytes and bits as in drive_bridge/protocol/lvsg.py, from the MCD 200 Profibus Module manual
-- (002): "LVSG Motor Starter Profile 2 Data Structure" (control byte 0: bit 0 Fwd Run, bit 3
-- Reset; byte 1: bit 4 Quick Stop; status byte 0: bit 0 Ready, bit 1 On, bit 2 Fault; byte 1:
-- bits 0-5 motor current % FLC (63 = 200 %, divide by 0.315), bit 7 Ramping), "... with
-- Extended Data Structure" (output byte 2: operating parameter request 1-4; input byte 2
-- bit 0: invalid parameter number, byte 3: echoed parameter number, bytes 4/5: value low/high;
-- parameter 1 product type (high byte bits 7-3) and software version, 2 trip code (high byte)
-- and MCD 200 state (low byte bits 0-3, flags bits 4-7), 3 average current (A), 4 motor
-- temperature (low byte)).
-- Written for Wireshark 4.0 (Lua 5.2) and later (Lua 5.3/5.4): no bit operators.

local proto = Proto('danfoss_lvsg', 'Danfoss LVSG image (MCD 200 Profibus Module)')

local function bits(value, low, width)
    return math.floor(value / 2 ^ low) % 2 ^ (width or 1)
end

local IMAGES = { [0] = 'output (control, master to starter)',
                 [1] = 'input (status, starter to master)' }
local PARAMETERS = { [1] = 'product type and software version', [2] = 'trip code and state',
                     [3] = 'average current (A)', [4] = 'motor temperature (%)' }
local STATES = {
    [0] = 'unknown (communication error between module and MCD 200)', [1] = 'ready',
    [2] = 'starting', [3] = 'running', [4] = 'stopping', [5] = 'not ready (restart delay)',
    [6] = 'fault (tripped)',
}
local TRIPS = {
    [1] = 'Excess start time', [2] = 'Motor overload', [3] = 'Motor thermistor',
    [4] = 'Phase imbalance', [5] = 'Supply frequency', [6] = 'Phase rotation',
    [8] = 'Power circuit', [15] = 'Communication failure between module and MCD 200',
    [16] = 'Communication failure between module and network', [255] = 'no trip',
}
local CURRENT_DIVISOR = 0.315

local f = {
    unit = ProtoField.uint8('danfoss_lvsg.unit', 'Gateway unit', base.DEC),
    image = ProtoField.uint8('danfoss_lvsg.image', 'Image', base.DEC, IMAGES),
    register = ProtoField.uint16('danfoss_lvsg.register', 'First register of the image',
                                 base.DEC),
    control0 = ProtoField.uint8('danfoss_lvsg.control0', 'Control byte 0', base.HEX),
    fwd_run = ProtoField.bool('danfoss_lvsg.fwd_run', 'Fwd Run', 8, nil, 0x01),
    reset = ProtoField.bool('danfoss_lvsg.reset', 'Reset', 8, nil, 0x08),
    control1 = ProtoField.uint8('danfoss_lvsg.control1', 'Control byte 1', base.HEX),
    quick_stop = ProtoField.bool('danfoss_lvsg.quick_stop',
                                 'Quick Stop (the stop on Fwd Run 1 -> 0 coasts)', 8, nil, 0x10),
    parameter_request = ProtoField.uint8('danfoss_lvsg.parameter_request',
                                         'Operating parameter request', base.DEC, PARAMETERS),
    status0 = ProtoField.uint8('danfoss_lvsg.status0', 'Status byte 0', base.HEX),
    ready = ProtoField.bool('danfoss_lvsg.ready', 'Ready', 8, nil, 0x01),
    on = ProtoField.bool('danfoss_lvsg.on', 'On (starting, running or soft stopping)', 8, nil,
                         0x02),
    fault = ProtoField.bool('danfoss_lvsg.fault', 'Fault (tripped)', 8, nil, 0x04),
    status1 = ProtoField.uint8('danfoss_lvsg.status1', 'Status byte 1', base.HEX),
    current_raw = ProtoField.uint8('danfoss_lvsg.current_raw', 'Motor current (63 = 200 % FLC)',
                                   base.DEC, nil, 0x3F),
    ramping = ProtoField.bool('danfoss_lvsg.ramping', 'Ramping', 8, nil, 0x80),
    current_pct_flc = ProtoField.double('danfoss_lvsg.current_pct_flc', 'Motor current (% FLC)'),
    invalid_parameter = ProtoField.bool('danfoss_lvsg.invalid_parameter',
                                        'Invalid parameter number', 8, nil, 0x01),
    parameter = ProtoField.uint8('danfoss_lvsg.parameter', 'Echoed parameter number', base.DEC,
                                 PARAMETERS),
    value = ProtoField.uint16('danfoss_lvsg.value', 'Parameter value', base.DEC_HEX),
    product_type = ProtoField.uint8('danfoss_lvsg.product_type', 'Product type (4 = MCD 200)',
                                    base.DEC),
    software_version = ProtoField.uint8('danfoss_lvsg.software_version', 'Software version',
                                        base.DEC),
    trip_code = ProtoField.uint8('danfoss_lvsg.trip_code', 'Trip code', base.DEC, TRIPS),
    state_byte = ProtoField.uint8('danfoss_lvsg.state_byte', 'MCD 200 state byte', base.HEX),
    state = ProtoField.uint8('danfoss_lvsg.state', 'MCD 200 state', base.DEC, STATES, 0x0F),
    positive_rotation = ProtoField.bool('danfoss_lvsg.positive_rotation',
                                        'Positive phase rotation', 8, nil, 0x10),
    current_above_flc = ProtoField.bool('danfoss_lvsg.current_above_flc',
                                        'Average current exceeds FLC', 8, nil, 0x20),
    rotation_validated = ProtoField.bool('danfoss_lvsg.rotation_validated',
                                         'Phase rotation validated', 8, nil, 0x40),
    comms_failure = ProtoField.bool('danfoss_lvsg.comms_failure',
                                    'Comms failure between module and MCD 200', 8, nil, 0x80),
    current_a = ProtoField.uint16('danfoss_lvsg.current_a', 'Average current (A)', base.DEC),
    temperature_pct = ProtoField.uint8('danfoss_lvsg.temperature_pct',
                                       'Motor temperature (% thermal capacity)', base.DEC),
}
local all_fields = {}
for _, field in pairs(f) do
    table.insert(all_fields, field)
end
proto.fields = all_fields

local e = {
    fault = ProtoExpert.new('danfoss_lvsg.tripped', 'The starter has tripped (Fault)',
                            expert.group.RESPONSE_CODE, expert.severity.WARN),
    invalid = ProtoExpert.new('danfoss_lvsg.invalid', 'Invalid operating parameter number',
                              expert.group.RESPONSE_CODE, expert.severity.WARN),
    bad_pref = ProtoExpert.new('danfoss_lvsg.bad_pref', 'danfoss_lvsg.slaves is not valid',
                               expert.group.PROTOCOL, expert.severity.ERROR),
}
proto.experts = { e.fault, e.invalid, e.bad_pref }

proto.prefs.slaves = Pref.string(
    'Slaves', '', 'unit:input_register:output_register[:basic|extended[:big|little]], ... '
    .. '(frame addresses, as gateway_input_register and gateway_output_register)')
proto.prefs.tcp_port = Pref.uint('Modbus TCP port', 502, 'Tells a Modbus TCP request from '
                                 .. 'a reply when the capture has no direction')

local fc_field = Field.new('modbus.func_code')
local rtu_unit_field = Field.new('mbrtu.unit_id')
local tcp_unit_field = Field.new('mbtcp.unit_id')
local src_port_field = Field.new('tcp.srcport')
local dst_port_field = Field.new('tcp.dstport')

-- The slaves of the preference, or nil and why not.
local function parse_slaves(text)
    local slaves = {}
    for entry in text:gmatch('[^,;%s]+') do
        local parts = {}
        for part in entry:gmatch('[^:]+') do
            table.insert(parts, part)
        end
        local unit, input, output = tonumber(parts[1]), tonumber(parts[2]), tonumber(parts[3])
        local module, order = parts[4] or 'extended', parts[5] or 'big'
        if unit == nil or input == nil or output == nil or #parts > 5
                or (module ~= 'basic' and module ~= 'extended')
                or (order ~= 'big' and order ~= 'little') then
            return nil, string.format('"%s" is not unit:input_register:output_register'
                                      .. '[:basic|extended[:big|little]]', entry)
        end
        local extended = module == 'extended'
        table.insert(slaves, {
            unit = unit, big = order == 'big',
            images = { [0] = { register = output, bytes = extended and 3 or 2 },
                       [1] = { register = input, bytes = extended and 6 or 2 } },
        })
    end
    return slaves
end

local last_read = {}
local reads = {}

function proto.init()
    last_read = {}
    reads = {}
end

-- Whether the frame is a request (true), a reply (false), or nil: not known.
local function is_request(pinfo)
    if pinfo.p2p_dir == 0 then
        return true
    elseif pinfo.p2p_dir == 1 then
        return false
    end
    local src, dst = src_port_field(), dst_port_field()
    if dst ~= nil and dst.value == proto.prefs.tcp_port then
        return true
    elseif src ~= nil and src.value == proto.prefs.tcp_port then
        return false
    end
    return nil
end

-- The registers a Modbus PDU carries: {start, count, [values offset]} (values 2 bytes a
-- register, big-endian), or nil. Reads: the request notes what is asked, its reply carries it.
local function registers_of(pdu, offset, code, request, pinfo, unit)
    local length = pdu:len() - offset
    if code == 3 and request and length >= 5 then
        if reads[pinfo.number] == nil then
            reads[pinfo.number] = true
            last_read[unit] = { start = pdu(offset + 1, 2):uint(),
                                count = pdu(offset + 3, 2):uint() }
        end
        return nil
    elseif code == 3 and not request and length >= 2 then
        if reads[pinfo.number] == nil then
            reads[pinfo.number] = last_read[unit] or false
            last_read[unit] = nil
        end
        local asked = reads[pinfo.number]
        local count = math.floor(pdu(offset + 1, 1):uint() / 2)
        if not asked or asked.count ~= count or length < 2 + 2 * count then
            return nil
        end
        return { start = asked.start, count = count, values = offset + 2 }
    elseif code == 6 and length >= 5 then
        return { start = pdu(offset + 1, 2):uint(), count = 1, values = offset + 3 }
    elseif code == 16 and request and length >= 6 then
        local count = pdu(offset + 3, 2):uint()
        if length < 6 + 2 * count then
            return nil
        end
        return { start = pdu(offset + 1, 2):uint(), count = count, values = offset + 6 }
    end
    return nil
end

-- The wire position of each image byte the registers carry: {[byte index] = tvb offset}.
local function image_bytes(image, big, carried)
    local positions, any = {}, false
    for index = 0, image.bytes - 1 do
        local register = image.register + math.floor(index / 2)
        local relative = register - carried.start
        if relative >= 0 and relative < carried.count then
            local first = index % 2 == 0
            local high = (first and big) or (not first and not big)
            positions[index] = carried.values + 2 * relative + (high and 0 or 1)
            any = true
        end
    end
    return any and positions or nil
end

local function add_byte(tree, pdu, at, field, children)
    local item = tree:add(field, pdu(at, 1))
    for _, child in ipairs(children) do
        item:add(child, pdu(at, 1))
    end
    return pdu(at, 1):uint(), item
end

local function add_output(tree, pdu, at, summary)
    if at[0] then
        local byte = add_byte(tree, pdu, at[0], f.control0, { f.fwd_run, f.reset })
        table.insert(summary, bits(byte, 0) == 1 and 'Fwd Run' or 'no Fwd Run')
        if bits(byte, 3) == 1 then table.insert(summary, 'Reset') end
    end
    if at[1] then
        local byte = add_byte(tree, pdu, at[1], f.control1, { f.quick_stop })
        if bits(byte, 4) == 1 then table.insert(summary, 'Quick Stop') end
    end
    if at[2] then
        local request = pdu(at[2], 1):uint()
        tree:add(f.parameter_request, pdu(at[2], 1))
        table.insert(summary, string.format('request parameter %d', request))
    end
end

local function add_parameter_value(tree, pdu, at, parameter, value, summary)
    local range = pdu(at[4], 1)
    local item = tree:add(f.value, range, value):set_generated()
    if parameter == 1 then
        item:add(f.product_type, range, bits(value, 11, 5)):set_generated()
        item:add(f.software_version, range, bits(value, 0, 8)):set_generated()
        table.insert(summary, string.format('product type %d', bits(value, 11, 5)))
    elseif parameter == 2 then
        local trip, state = bits(value, 8, 8), bits(value, 0, 8)
        item:add(f.trip_code, pdu(at[5], 1), trip)
        local state_item = item:add(f.state_byte, range, state)
        for _, child in ipairs({ f.state, f.positive_rotation, f.current_above_flc,
                                 f.rotation_validated, f.comms_failure }) do
            state_item:add(child, range, state)
        end
        table.insert(summary, string.format('state %s, trip %s', STATES[bits(state, 0, 4)]
                                            or tostring(bits(state, 0, 4)),
                                            TRIPS[trip] or tostring(trip)))
    elseif parameter == 3 then
        item:add(f.current_a, range, value):set_generated()
        table.insert(summary, string.format('current %d A', value))
    elseif parameter == 4 then
        item:add(f.temperature_pct, range, bits(value, 0, 8)):set_generated()
        table.insert(summary, string.format('temperature %d %%', bits(value, 0, 8)))
    end
end

local function add_input(tree, pdu, at, summary)
    if at[0] then
        local byte, item = add_byte(tree, pdu, at[0], f.status0, { f.ready, f.on, f.fault })
        local flags = {}
        if bits(byte, 0) == 1 then table.insert(flags, 'Ready') end
        if bits(byte, 1) == 1 then table.insert(flags, 'On') end
        if bits(byte, 2) == 1 then
            table.insert(flags, 'Fault')
            item:add_proto_expert_info(e.fault)
        end
        table.insert(summary, #flags > 0 and table.concat(flags, ' ') or 'not ready')
    end
    if at[1] then
        local byte = add_byte(tree, pdu, at[1], f.status1, { f.current_raw, f.ramping })
        local pct = bits(byte, 0, 6) / CURRENT_DIVISOR
        tree:add(f.current_pct_flc, pdu(at[1], 1), pct):set_generated()
        if bits(byte, 7) == 1 then table.insert(summary, 'Ramping') end
        table.insert(summary, string.format('%.0f %% FLC', pct))
    end
    if at[2] then
        local item = tree:add(f.invalid_parameter, pdu(at[2], 1))
        if bits(pdu(at[2], 1):uint(), 0) == 1 then
            item:add_proto_expert_info(e.invalid)
            table.insert(summary, 'invalid parameter')
        end
    end
    if at[3] then
        tree:add(f.parameter, pdu(at[3], 1))
    end
    if at[3] and at[4] and at[5] then
        local value = pdu(at[5], 1):uint() * 256 + pdu(at[4], 1):uint()
        add_parameter_value(tree, pdu, at, pdu(at[3], 1):uint(), value, summary)
    end
end

function proto.dissector(tvb, pinfo, tree)
    if proto.prefs.slaves == '' then
        return
    end
    local code_info = fc_field()
    if code_info == nil or code_info.source == nil then
        return
    end
    local slaves, problem = parse_slaves(proto.prefs.slaves)
    if slaves == nil then
        tree:add(proto):add_proto_expert_info(e.bad_pref, 'danfoss_lvsg.slaves: ' .. problem)
        return
    end
    local unit_info = rtu_unit_field() or tcp_unit_field()
    local request = is_request(pinfo)
    if unit_info == nil or request == nil then
        return
    end
    local unit, pdu, offset = unit_info.value, code_info.source, code_info.offset
    local carried = registers_of(pdu, offset, code_info.value, request, pinfo, unit)
    if carried == nil then
        return
    end
    for _, slave in ipairs(slaves) do
        if slave.unit == unit then
            for kind = 0, 1 do
                local image = slave.images[kind]
                local at = image_bytes(image, slave.big, carried)
                if at then
                    local root = tree:add(proto, pdu(offset))
                    root:add(f.unit, unit):set_generated()
                    root:add(f.image, kind):set_generated()
                    root:add(f.register, image.register):set_generated()
                    local summary = {}
                    if kind == 0 then
                        add_output(root, pdu, at, summary)
                    else
                        add_input(root, pdu, at, summary)
                    end
                    local text = string.format('LVSG unit %d %s @%d: %s', unit,
                                               kind == 0 and 'control' or 'status',
                                               image.register, table.concat(summary, ', '))
                    root:append_text(', ' .. text)
                    pinfo.cols.info:append(' | ' .. text)
                end
            end
        end
    end
end

register_postdissector(proto)
